"""Statistics of a Monte Carlo table: per-metric summary and requirement verdicts.

Requirement verdict (coverage p, confidence c): with n samples of which k fail the requirement
(a sample that did not run to the end counts as failing), the number of failures X of n
independent cases that each fail with probability 1 - p is Binomial(n, 1 - p). The requirement
is shown to hold in at least p of the cases with confidence c iff seeing k or fewer failures
would be unlikely were the failure probability 1 - p:

    P(X <= k | n, 1 - p) <= 1 - c,

which is the same as the one-sided Clopper-Pearson lower bound on the success probability
being >= p. With zero failures this reads p**n <= 1 - c, so the verdict needs at least
``n >= ln(1 - c) / ln(p)`` samples (852 for p = 0.9973, c = 0.9).
"""

from __future__ import annotations

import math
import warnings
from contextlib import contextmanager

import numpy as np
from scipy import stats as sps

from ...run.metrics import METRICS

__all__ = ["PERCENTILES", "percentile_needs", "quiet_nan", "metric_stats", "verdict", "n_needed", "requirement_verdicts",
           "success_lower_bound", "PASS", "FAIL", "NOT_SHOWN"]

#: percentiles reported per metric (each only where the sample count supports it)
PERCENTILES = (50.0, 90.0, 99.0, 99.73)


def percentile_needs(p: float) -> int:
    """Samples the ``p``-th percentile needs: ``n >= 1 / (1 - p/100)``, so that at least one
    sample is expected beyond it (below that, the "percentile" is the largest sample under
    another name: 2 for p50, 10 for p90, 100 for p99, 371 for p99.73). p100 (the max) needs 1."""
    tail = 1.0 - p / 100.0
    return 1 if tail <= 0 else int(math.ceil(1.0 / tail - 1e-9))


@contextmanager
def quiet_nan():
    """numpy's "All-NaN slice" / "Mean of empty slice" warnings off: an empty or all-NaN column
    (every sample failed before a time) has no statistic, and NaN says so."""
    with warnings.catch_warnings(), np.errstate(all="ignore"):
        warnings.simplefilter("ignore", RuntimeWarning)
        yield


def n_needed(coverage: float, confidence: float, failures: int = 0) -> int:
    """Smallest n for which ``failures`` failures pass at (coverage, confidence)."""
    if failures == 0:
        return int(math.ceil(math.log(1.0 - confidence) / math.log(coverage) - 1e-12))
    hi = failures + 1
    while not verdict(hi, failures, coverage, confidence):  # P(X <= k) falls as n grows
        hi *= 2
    lo = hi // 2  # fails (or is below k + 1)
    while hi - lo > 1:
        mid = (lo + hi) // 2
        lo, hi = (lo, mid) if verdict(mid, failures, coverage, confidence) else (mid, hi)
    return hi


def success_lower_bound(n: int, failures: int, confidence: float) -> float:
    """One-sided Clopper-Pearson lower bound on the success probability at ``confidence``."""
    if failures >= n:
        return 0.0
    return float(sps.beta.ppf(1.0 - confidence, n - failures, failures + 1))


def verdict(n: int, failures: int, coverage: float, confidence: float) -> bool:
    """Whether ``failures`` of ``n`` show the requirement holds in >= coverage of cases with
    ``confidence``: ``P(X <= failures | n, 1 - coverage) <= 1 - confidence``."""
    return bool(sps.binom.cdf(failures, n, 1.0 - coverage) <= 1.0 - confidence)


def metric_stats(df, metrics=None) -> dict:
    """Per metric over the samples that ran to the end (status ok) and have a value: count, mean,
    std (ddof 1), percentiles :data:`PERCENTILES` (None when ``count`` is below
    :func:`percentile_needs`), min / max with the index of the sample."""
    ok = df[df["status"] == "ok"]
    out = {}
    for name in metrics or METRICS:
        if name not in ok:
            continue
        v = ok[name].to_numpy(dtype=float)
        good = ~np.isnan(v)
        if not good.any():
            continue
        v, idx = v[good], ok["index"].to_numpy()[good]
        s = {"unit": METRICS[name].unit, "count": int(len(v)), "mean": float(np.mean(v)),
             "std": float(np.std(v, ddof=1)) if len(v) > 1 else math.nan}
        for p in PERCENTILES:  # None (blank) where n cannot support it: see percentile_needs
            s[f"p{p:g}"] = float(np.percentile(v, p)) if len(v) >= percentile_needs(p) else None
        s["min"], s["min_index"] = float(v.min()), int(idx[int(np.argmin(v))])
        s["max"], s["max_index"] = float(v.max()), int(idx[int(np.argmax(v))])
        out[name] = s
    return out


#: the three verdicts of a requirement (``summary.json`` ``verdict``, the printed word)
PASS, FAIL, NOT_SHOWN = "PASS", "FAIL", "NOT SHOWN"


def requirement_verdicts(df, requirements) -> list[dict]:
    """One verdict per ``[[montecarlo.requirement]]`` over the table ``df``.

    ``verdict``: :data:`PASS` when the samples show the requirement (:func:`verdict`);
    :data:`FAIL` when they do not and at least one sample failed it (a sample that did not run
    to the end counts as failing); :data:`NOT_SHOWN` when none failed but n is too small to show
    it at its coverage and confidence (more samples can still show it), with ``note`` saying
    how many it needs. ``pass`` is ``verdict == PASS``."""
    out = []
    n = len(df)
    for r in requirements:
        v = df[r.metric].to_numpy(dtype=float) if r.metric in df else np.full(n, np.nan)
        ran = (df["status"] == "ok").to_numpy()
        with np.errstate(invalid="ignore"):
            met = (v <= r.max) if r.max is not None else (v >= r.min)
        met &= ran & ~np.isnan(v)
        k = int(n - met.sum())
        need = n_needed(r.coverage, r.confidence)
        ok = verdict(n, k, r.coverage, r.confidence)
        word = PASS if ok else (FAIL if k else NOT_SHOWN)
        d = {"metric": r.metric, "bound": "max" if r.max is not None else "min",
             "limit": r.max if r.max is not None else r.min, "coverage": r.coverage,
             "confidence": r.confidence, "n": n, "failures": k, "not_run": int(n - ran.sum()),
             "verdict": word, "pass": ok, "success_lower_bound": success_lower_bound(n, k, r.confidence),
             "n_needed_zero_failures": need}
        d.update({k: getattr(r, k) for k in ("id", "text") if getattr(r, k) is not None})
        if word == NOT_SHOWN:
            d["note"] = (f"0 of {n} failed; needs >= {need} samples for {100 * r.confidence:g} % confidence "
                         f"that at most {100 * (1 - r.coverage):.4g} % fail")
        elif word == FAIL and n < need:
            d["note"] = f"{k} failure(s); n = {n} is below the {need} that even 0 failures need"
        elif word == FAIL:
            d["note"] = f"{k} failure(s) of {n}: coverage {r.coverage:g} not shown at confidence {r.confidence:g}"
        out.append(d)
    return out
