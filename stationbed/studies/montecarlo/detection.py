"""Fault detection statistics of a Monte Carlo study (issue 34 item 4; docs/faults.md).

Per sample, against the truth drawn for it (never told to flight software), the columns
:data:`COLUMNS` (prefix ``detect.``): whether a CMG fault occurred (``fault_occurred``, the
earliest of the scene's CMG-target ``[[fault]]`` s that occurred; its time ``fault_t_s`` and unit
``fault_unit``), whether the CMG detector declared one (``declared``, from the ``fdir_detect_s``
/ ``fdir_unit`` metrics: time ``t_s``, unit ``unit``), ``latency_s`` = declaration - fault time,
``unit_right`` (the unit blamed is the failed one) and ``false_alarm`` (declared with no fault,
or before it).

Over the samples that ran to the end (:func:`detection_summary`):

* **detection probability**: declared / faulted, with the two-sided Clopper-Pearson interval
  (exact: beta quantiles) and Wilson's score interval at :data:`CONFIDENCE`;
* **isolation**: the right unit / declared, Clopper-Pearson;
* **latency**: median and percentiles (each where n supports it, stats.percentile_needs) with a
  distribution-free order-statistic interval (:func:`quantile_interval`);
* **false alarms**: declarations on the samples *without* a fault (a ``probability`` < 1 gives
  them), with the one-sided Clopper-Pearson upper bound, against the detector's stated
  probability of an alarm over the run's length, ``1 - exp(-rate x T)`` with the rate of
  loop/fdir.py ``false_alarms_per_hour``;
* **requirements under faults**: the scene's ``[[montecarlo.requirement]]`` verdicts
  (stats.requirement_verdicts) over the faulted samples and over the others.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import stats as sps

from ...loop.fdir import false_alarms_per_hour
from ...scene.faults import FAULT_KINDS
from .faults import fault_id
from .stats import percentile_needs, quiet_nan, requirement_verdicts

__all__ = ["CONFIDENCE", "COLUMNS", "PREFIX", "clopper_pearson", "wilson", "binomial_upper", "quantile_interval",
           "detection_columns", "detection_summary", "detection_text", "LATENCY_PERCENTILES"]

#: two-sided confidence of the intervals (one-sided for the false-alarm upper bound)
CONFIDENCE = 0.95
#: latency percentiles reported (each where the count supports it)
LATENCY_PERCENTILES = (50.0, 90.0, 99.0)
PREFIX = "detect."
COLUMNS = tuple(PREFIX + c for c in ("fault_occurred", "fault_t_s", "fault_unit", "declared", "t_s", "unit",
                                     "latency_s", "unit_right", "false_alarm"))


def clopper_pearson(k: int, n: int, confidence: float = CONFIDENCE) -> tuple[float, float]:
    """Two-sided exact interval of a binomial proportion from ``k`` of ``n``: the beta quantiles
    ``B(a/2; k, n-k+1)`` and ``B(1-a/2; k+1, n-k)`` (0 and 1 at the ends); (nan, nan) for n = 0."""
    if n <= 0:
        return math.nan, math.nan
    a = 1.0 - confidence
    lo = 0.0 if k <= 0 else float(sps.beta.ppf(a / 2, k, n - k + 1))
    hi = 1.0 if k >= n else float(sps.beta.ppf(1 - a / 2, k + 1, n - k))
    return lo, hi


def wilson(k: int, n: int, confidence: float = CONFIDENCE) -> tuple[float, float]:
    """Wilson's score interval of a binomial proportion; (nan, nan) for n = 0."""
    if n <= 0:
        return math.nan, math.nan
    z = float(sps.norm.isf((1.0 - confidence) / 2))
    p = k / n
    mid = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z / (1 + z * z / n) * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return max(0.0, mid - half), min(1.0, mid + half)


def binomial_upper(k: int, n: int, confidence: float = CONFIDENCE) -> float:
    """One-sided Clopper-Pearson upper bound on the proportion from ``k`` of ``n`` (``1 - (1 -
    c)^(1/n)`` at k = 0: the "rule of three" 3/n at 95 %); nan for n = 0."""
    if n <= 0:
        return math.nan
    return 1.0 if k >= n else float(sps.beta.ppf(confidence, k + 1, n - k))


def quantile_interval(x, p: float, confidence: float = CONFIDENCE):
    """Distribution-free interval of the ``p``-th percentile: order statistics ``x_(l) <=
    x_(u)`` (1-based) with ``P(x_(l) <= ξ < x_(u)) = F(u-1) - F(l-1) >= confidence``, ``F`` the
    Binomial(n, p/100) cdf, l and u as near the middle as that allows; None when n is too small
    for any pair to reach it."""
    x = np.sort(np.asarray(x, dtype=float))
    n, q = len(x), p / 100.0
    if n == 0:
        return None
    a = (1.0 - confidence) / 2
    j = int(sps.binom.ppf(a, n, q))  # the smallest j with F(j) >= a
    lo = j if sps.binom.cdf(j, n, q) > a else j + 1  # l: the largest with F(l - 1) <= a
    hi = int(sps.binom.ppf(1 - a, n, q)) + 1  # u - 1: the smallest with F(u - 1) >= 1 - a
    if lo < 1 or hi > n:
        return None
    return float(x[lo - 1]), float(x[hi - 1])


def _cmg_faults(scene) -> list[int]:
    return [i for i, f in enumerate(scene.fault or []) if FAULT_KINDS[f.kind].target == "cmg"]


def _drawn(df, scene, i: int, field: str) -> np.ndarray:
    """A fault's value per sample: its drawn column (any spelling of its key) else the scene's."""
    fid = fault_id(scene, i)
    for col in (f"fault.{fid}.{field}", f"fault.{i}.{field}", f"fault[{i}].{field}"):
        if col in df:
            return df[col].to_numpy(dtype=float)
    return np.full(len(df), float(getattr(scene.fault[i], field)))


def detection_columns(df, scene) -> dict[str, np.ndarray]:
    """The per-sample :data:`COLUMNS` (module docstring); {} when the scene has no ``[fdir]`` or
    the table no ``fdir_detect_s``."""
    if getattr(scene, "fdir", None) is None or "fdir_detect_s" not in df:
        return {}
    n = len(df)
    occ, t_f, u_f = np.zeros(n, bool), np.full(n, np.inf), np.full(n, np.nan)
    for i in _cmg_faults(scene):
        col = f"fault.{fault_id(scene, i)}.occurred"
        here = df[col].to_numpy(dtype=float) > 0.5 if col in df else np.full(n, scene.fault[i].enabled)
        t, u = _drawn(df, scene, i, "t"), _drawn(df, scene, i, "unit")
        first = here & (t < t_f)
        t_f, u_f, occ = np.where(first, t, t_f), np.where(first, u, u_f), occ | here
    t_f = np.where(occ, t_f, np.nan)
    t_d = df["fdir_detect_s"].to_numpy(dtype=float)
    declared = np.nan_to_num(t_d, nan=-1.0) >= 0.0
    t_d = np.where(declared, t_d, np.nan)
    u_d = np.where(declared, df["fdir_unit"].to_numpy(dtype=float), np.nan) if "fdir_unit" in df else np.full(n, np.nan)
    with np.errstate(invalid="ignore"):
        early = declared & occ & (t_d < t_f)
        hit = declared & occ & ~early
        lat = np.where(hit, t_d - t_f, np.nan)
        right = np.where(hit, (u_d == u_f).astype(float), np.nan)
    false = declared & (~occ | early)
    c = dict(fault_occurred=occ.astype(float), fault_t_s=t_f, fault_unit=u_f, declared=declared.astype(float),
             t_s=t_d, unit=u_d, latency_s=lat, unit_right=right, false_alarm=false.astype(float))
    return {PREFIX + k: v for k, v in c.items()}


def _rate(k: int, n: int) -> dict:
    cp, w = clopper_pearson(k, n), wilson(k, n)
    return {"k": k, "n": n, "rate": k / n if n else math.nan, "clopper_pearson": list(cp), "wilson": list(w)}


def detection_summary(scene, df) -> dict | None:
    """The study-level statistics (module docstring) over the samples that ran to the end; None
    without detection columns."""
    cols = detection_columns(df, scene)
    if not cols:
        return None
    ok = (df["status"] == "ok").to_numpy()
    g = {k[len(PREFIX):]: v[ok] for k, v in cols.items()}
    faulted, declared = g["fault_occurred"] > 0.5, g["declared"] > 0.5
    hit = faulted & declared & ~(g["false_alarm"] > 0.5)
    lat = g["latency_s"][hit]
    latency = {"count": int(len(lat))}
    with quiet_nan():
        latency.update(min=float(np.min(lat)) if len(lat) else None, max=float(np.max(lat)) if len(lat) else None)
    for p in LATENCY_PERCENTILES:
        enough = len(lat) >= percentile_needs(p)
        latency[f"p{p:g}"] = float(np.percentile(lat, p)) if enough else None
        ci = quantile_interval(lat, p) if enough else None
        latency[f"p{p:g}_interval"] = list(ci) if ci else None
    clean = ~faulted
    k_fa, n_fa = int((declared & clean).sum()), int(clean.sum())
    fd, period = scene.fdir, scene.controller.period
    rate_h = false_alarms_per_hour(fd.cmg_alpha, fd.cmg_persistence, 3600.0 / period)
    hours = scene.simulation.duration / 3600.0
    stated = -math.expm1(-rate_h * hours)
    upper = binomial_upper(k_fa, n_fa)
    false = {"k": k_fa, "n": n_fa, "rate": k_fa / n_fa if n_fa else None, "upper": upper,
             "confidence": CONFIDENCE, "stated_per_run": stated, "stated_per_hour": rate_h, "run_hours": hours,
             # the stated probability is not contradicted: seeing k or more alarms is not unlikely under it
             "consistent": bool(n_fa == 0 or sps.binom.sf(k_fa - 1, n_fa, stated) > 1.0 - CONFIDENCE),
             "early_in_faulted": int((faulted & (g["false_alarm"] > 0.5)).sum())}
    reqs = scene.montecarlo.requirement
    okdf = df[ok]
    return {"n_ok": int(ok.sum()), "confidence": CONFIDENCE, "faulted": int(faulted.sum()),
            "detection": _rate(int(hit.sum()), int(faulted.sum())),
            "isolation": _rate(int(np.nansum(g["unit_right"][hit])), int(hit.sum())),
            "latency_s": latency, "false_alarms": false,
            "requirements_faulted": requirement_verdicts(okdf[faulted], reqs),
            "requirements_no_fault": requirement_verdicts(okdf[clean], reqs) if clean.any() else []}


def detection_text(d: dict) -> list[str]:
    """The summary's detection lines (report.table_text)."""
    pc = round(100 * d["confidence"])
    det, iso, lat, fa = d["detection"], d["isolation"], d["latency_s"], d["false_alarms"]

    def frac(r):
        lo, hi = r["clopper_pearson"]
        return f"{r['k']} of {r['n']} (Clopper-Pearson {pc} %: {lo:.4f}-{hi:.4f})" if r["n"] else "none"

    out = [f"fault detection: declared {frac(det)}; right unit {frac(iso)}"]
    parts = []
    for p in LATENCY_PERCENTILES:
        v, ci = lat[f"p{p:g}"], lat[f"p{p:g}_interval"]
        if v is not None:
            parts.append(f"p{p:g} {v:.3g} s" + (f" [{ci[0]:.3g}, {ci[1]:.3g}]" if ci else " [n too small]"))
    if lat["count"]:
        out.append(f"detection latency ({lat['count']}): " + ", ".join(parts + [f"max {lat['max']:.3g} s"]))
    if not fa["n"]:  # every sample drew its fault: no flight to count false alarms on (upper is nan)
        out.append(f"false alarms: no sample without a fault (nothing to bound); {fa['early_in_faulted']} before a fault")
    else:
        out.append(f"false alarms: {fa['k']} of {fa['n']} samples without a fault (upper {pc} % bound "
                   f"{fa['upper']:.3g}; stated {fa['stated_per_run']:.3g} per run of {fa['run_hours']:.3g} h: "
                   f"{'consistent' if fa['consistent'] else 'NOT consistent'}); {fa['early_in_faulted']} before a fault")
    for label, key in (("with a fault", "requirements_faulted"), ("without", "requirements_no_fault")):
        for r in d[key]:
            out.append(f"  {label}: {r['metric']} {r['verdict']} ({r['failures']} of {r['n']} fail)")
    return out
