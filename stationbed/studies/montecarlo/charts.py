"""Monte Carlo charts (PNG, matplotlib Agg): histograms per metric, attitude-error and |h|
envelopes over time (percentile bands), and a metric against the drawn value it depends on
most (largest |Spearman rank correlation|)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy import stats as sps

from ...core.plotting import save_png
from ...run.metrics import METRICS
from ..plotting import pyplot
from .stats import percentile_needs, quiet_nan

__all__ = ["histograms", "envelopes", "scatter", "strongest_driver", "ENVELOPE_COVERAGE", "envelope_bands",
           "band_limits"]

#: the central bands of the envelope charts: the fraction of the samples each holds at every time
ENVELOPE_COVERAGE = (0.9973, 0.90, 0.50)


def envelope_bands(n: int) -> list[tuple[float, float, float, str]]:
    """The bands ``(lo, hi, coverage, label)`` an envelope chart of ``n`` samples draws, widest first.

    A central band of coverage c lies between the percentiles (1 - c)/2 and (1 + c)/2, each an
    order statistic (:func:`band_limits`), so it holds at least c of the samples at every time.
    It is drawn only when n supports its tails (:func:`.stats.percentile_needs`: at least one
    sample expected beyond each edge); where the widest band is not supported, the band of all
    n samples (min to max) is drawn in its place, labelled as what it is."""
    bands = []
    for c in ENVELOPE_COVERAGE:
        lo, hi = 50.0 * (1.0 - c), 50.0 * (1.0 + c)
        if n >= percentile_needs(hi):
            bands.append((lo, hi, c, f"p{lo:.3g}-p{hi:.3g}: at least {100 * c:g} % of samples"))
        elif c == ENVELOPE_COVERAGE[0]:
            bands.append((0.0, 100.0, 1.0, f"min-max: all {n} samples (too few for a {100 * c:g} % band: "
                                           f"n >= {percentile_needs(hi)})"))
    return bands


def band_limits(y, lo: float, hi: float):
    """The band's edges per time over the samples (rows of ``y``): the order statistics below
    ``lo`` and above ``hi`` (numpy's "lower" / "higher" percentiles), NaN samples left out."""
    with quiet_nan():
        return (np.nanpercentile(y, lo, axis=0, method="lower"), np.nanpercentile(y, hi, axis=0, method="higher"))
#: an envelope whose worst value is this many times the median's largest is drawn on a log axis
LOG_SPREAD = 30.0


def _ok_values(df, name):
    ok = df[df["status"] == "ok"]
    v = ok[name].to_numpy(dtype=float)
    return v[np.isfinite(v)]  # NaN: no value; inf (an error that grew without bound, a filter that never converged): no bin


def histograms(df, out: Path, requirements=()) -> list[Path]:
    """One ``hist_<metric>.png`` per metric with values; a requirement's limit as a red line."""
    plt = pyplot()
    paths = []
    limits = {r.metric: (r.max if r.max is not None else r.min) for r in requirements}
    for name, m in METRICS.items():
        if name not in df:
            continue
        v = _ok_values(df, name)
        if not len(v):
            continue
        fig, ax = plt.subplots(figsize=(6.4, 4.0))
        bins = min(50, max(5, int(np.sqrt(len(v)))))
        if np.ptp(v) == 0:
            bins = 1
        elif v.min() > 0 and v.max() > LOG_SPREAD * np.median(v):  # a heavy tail: log-spaced bins
            bins = np.geomspace(v.min(), v.max(), bins + 1)
            ax.set_xscale("log")
        ax.hist(v, bins=bins, color="#4c72b0", edgecolor="white")
        if name in limits:
            ax.axvline(limits[name], color="red", lw=1.5, label=f"requirement {limits[name]:g}")
            ax.set_ylim(top=ax.get_ylim()[1] * 1.2)  # room for the legend above the bars
            ax.legend(loc="upper center", fontsize=8)
        ax.set_xlabel(f"{name} [{m.unit}]")
        ax.set_ylabel("samples")
        ax.set_title(f"{name}: {len(v)} samples, median {np.median(v):.3g}, max {v.max():.3g}", fontsize=10)
        ax.grid(alpha=0.3)
        p = out / f"hist_{name}.png"
        save_png(plt, fig, p)
        paths.append(p)
    return paths


def envelopes(t, env, out: Path, title: str) -> list[Path]:
    """``envelope_att_err.png`` and ``envelope_h.png``: percentile bands over the samples per
    time, the median and the worst sample's curve.

    Parameters
    ----------
    t : ndarray, shape (T,)  Times [s].
    env : ndarray, shape (n, T, 2)  Attitude error [deg] and |h| / capacity per sample.
    """
    plt = pyplot()
    paths = []
    t_orbit = t / 60.0
    for j, (fname, label) in enumerate((("envelope_att_err.png", "attitude error [deg]"),
                                        ("envelope_h.png", "|h| / capacity"))):
        y = env[:, :, j]
        if np.all(np.isnan(y)):
            continue
        fig, ax = plt.subplots(figsize=(7.5, 4.2))
        for (lo, hi, _, lab), a in zip(envelope_bands(len(y)), (0.18, 0.3, 0.45)):
            ax.fill_between(t_orbit, *band_limits(y, lo, hi), color="#4c72b0", alpha=a, lw=0, label=lab)
        with quiet_nan():
            median = np.nanmedian(y, axis=0)
            worst = int(np.nanargmax(np.nanmax(y, axis=1)))
            bottom = max(np.nanmin(y) / 2, 1e-6 * np.nanmax(y))
            spread = np.nanmax(y) > LOG_SPREAD * max(np.nanmax(median), 1e-300)  # outliers would flatten the bulk
        ax.plot(t_orbit, median, color="#1f3b6f", lw=1.5, label="median")
        ax.plot(t_orbit, y[worst], color="#c44e52", lw=1.0, label=f"worst sample (row {worst})")
        if spread:
            ax.set_yscale("log")
            ax.set_ylim(bottom=bottom)
        ax.set_xlabel("time [min]")
        ax.set_ylabel(label)
        ax.set_title(f"{title}: {label} over {len(y)} samples", fontsize=10)
        ax.grid(alpha=0.3)
        ax.legend(loc="best", fontsize=8)
        p = out / fname
        save_png(plt, fig, p)
        paths.append(p)
    return paths


def strongest_driver(df, metric: str, drawn: list[str]) -> tuple[str, float] | None:
    """The drawn column with the largest |Spearman rank correlation| with ``metric`` over the
    samples that ran (None: no drawn column varies)."""
    ok = df[(df["status"] == "ok") & df[metric].notna()]
    best = None
    for c in drawn:
        if ok[c].dtype.kind not in "biuf":  # a choice recorded as text (cmg.failed): no order to rank
            continue
        x = ok[c].to_numpy(dtype=float)
        if len(x) < 3 or np.ptp(x) == 0 or np.ptp(ok[metric].to_numpy(dtype=float)) == 0:
            continue
        rho = sps.spearmanr(x, ok[metric].to_numpy(dtype=float)).statistic
        if np.isfinite(rho) and (best is None or abs(rho) > abs(best[1])):
            best = (c, float(rho))
    return best


def scatter(df, metric: str, drawn: list[str], out: Path) -> Path | None:
    """``scatter_<metric>.png``: the metric against its strongest driver."""
    found = strongest_driver(df, metric, drawn)
    if found is None:
        return None
    col, rho = found
    plt = pyplot()
    ok = df[(df["status"] == "ok") & df[metric].notna()]
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    ax.scatter(ok[col], ok[metric], s=10, alpha=0.6, color="#4c72b0")
    ax.set_xlabel(col)
    ax.set_ylabel(f"{metric} [{METRICS[metric].unit}]")
    ax.set_title(f"{metric} vs {col} (Spearman ρ = {rho:+.2f})", fontsize=10)
    ax.grid(alpha=0.3)
    p = out / f"scatter_{metric}.png"
    save_png(plt, fig, p)
    return p
