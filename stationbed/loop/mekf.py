"""Multiplicative extended Kalman filter: attitude and gyro bias from a gyro and star trackers.

Markley, "Attitude error representations for Kalman filtering", JGCD 26(2), 2003; Crassidis &
Junkins, *Optimal Estimation of Dynamic Systems*, 2nd ed., §7.2 (Table 7.1). In the project's
conventions (DESIGN §3):

* truth ``q_BN = q̂ ⊗ δq(δα)``, ``C_BN = (E - [δα×]) Ĉ_BN`` to first order; error state
  ``Δx = (δα, Δβ)`` (6), ``Δβ = β - β̂``; the filter state is ``(q̂_BN, β̂, P)``
  (:data:`FILTER`, P 6 x 6).
* Propagation over one gyro sample Δt with ``ω̂ = ω̃ - β̂`` held: ``q̂ ← q̂ ⊗ exp(ω̂ Δt)``
  (exact for a rate constant over the sample), ``P ← Φ P Φᵀ + Q`` with the closed forms

  ``Φ₁₁ = E - [ω̂×] sin(wΔt)/w + [ω̂×]² (1 - cos wΔt)/w²``
  ``Φ₁₂ = [ω̂×] (1 - cos wΔt)/w² - E Δt - [ω̂×]² (wΔt - sin wΔt)/w³``, ``Φ₂₁ = 0``, ``Φ₂₂ = E``
  ``Q₁₁ = (σ_v² Δt + σ_u² Δt³/3) E``, ``Q₁₂ = Q₂₁ = -(σ_u² Δt²/2) E``, ``Q₂₂ = σ_u² Δt E``

  (w = |ω̂|; series for small wΔt). Q is the discrete covariance of the Farrenkopf gyro
  (stationbed/loop/gyro.py), so a filter tuned from the gyro's table is consistent with it.
* Update with one star-tracker head (mounting ``q_SB``, noise-equivalent angles r): residual
  ``z = 2 vec(δq_r)/w(δq_r)``, ``δq_r = (q̂ ⊗ q_SB)⁻¹ ⊗ q̃_SN`` (S components), ``z ≈ C_SB δα + ν``,
  so ``H = [C_SB, 0]``, ``R = diag(r_cross², r_cross², r_about²)``;
  ``K = P Hᵀ (H P Hᵀ + R)⁻¹``, ``Δx̂ = K z``, ``q̂ ← q̂ ⊗ δq(δα̂)``, ``β̂ ← β̂ + Δβ̂``,
  ``P ← P − K (P Hᵀ)ᵀ`` (the Joseph form's value for this optimal gain, exactly symmetric: see
  :func:`update`), each valid fresh head in turn.
* A head with latency L: the sample of L ago is compared with the estimate carried back by the
  filter's own turn since then (a delay line of turns per head in the state, :attr:`Mekf.state`);
  see :func:`update` for H and the correlated noise of the turn.

Everything is a casadi expression: one :meth:`Mekf.function` per tick, compiled once
(:meth:`Mekf.compiled`) and ready to be inlined in a fused loop. :meth:`Mekf.report_function`
gives what only a test bed can know: the estimation error against truth, the 3σ bounds and the
normalised estimation error squared ``NEES = Δxᵀ P⁻¹ Δx``.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..core.compile import FastCall, compile_functions
from ..core.linalg import inv3
from ..core.rotation import dcm, quat_conj, quat_mult, skew
from .gyro import RateGyro
from .layout import Layout
from .star_tracker import StarTracker

__all__ = ["FILTER", "Mekf", "propagate", "update", "attitude_error", "rotation_increment", "SERIES_BELOW"]

#: the filter's state: estimate of q_BN (scalar first), of the gyro bias [rad/s], covariance of
#: the error state (δα [rad], Δβ [rad/s])
FILTER = Layout(q_BN=4, bias_B=3, P=(6, 6))

#: below this rotation per step (w Δt) [rad] Φ's coefficients are their Taylor series (through
#: x⁶: truncation < 2e-15 relative at 0.1; above it the closed forms lose < 1e-13 to cancellation)
SERIES_BELOW = 0.1

#: a rate magnitude below every physical one [rad/s]: keeps w > 0 in the closed forms' branch,
#: whose values casadi's if_else computes (and would pass on as NaN) even where the series is
#: chosen; w³ of it is still a normal double
_TINY_RATE = 1e-30


def _coefficients(w, dt):
    """``sin(wΔt)/w``, ``(1 - cos wΔt)/w²``, ``(wΔt - sin wΔt)/w³``, accurate at every w >= 0."""
    x = w * dt
    ws = ca.fmax(w, _TINY_RATE)
    xs = ws * dt
    s_half = ca.sin(xs / 2)  # the sine and cosine of the turn's half angle: rotation_increment's too
    half = s_half / ws
    sin_x = 2 * s_half * ca.cos(xs / 2)  # sin(wΔt) from them: no sine of its own
    exact = (sin_x / ws, 2 * half * half, (xs - sin_x) / ws**3)
    x2 = x * x
    # the terms' factorials as reciprocals (a product where a division costs several: x2 is
    # ~1e-8 at station rates, so the terms' last bits do not reach the sums')
    r = {k: 1.0 / k for k in (6, 20, 42, 24, 30, 56, 120, 72)}
    series = (
        dt * (1 - x2 * r[6] * (1 - x2 * r[20] * (1 - x2 * r[42]))),
        dt**2 * (0.5 - x2 * r[24] * (1 - x2 * r[30] * (1 - x2 * r[56]))),
        dt**3 * (1.0 / 6 - x2 * r[120] * (1 - x2 * r[42] * (1 - x2 * r[72]))),
    )
    small = x < SERIES_BELOW
    return [ca.if_else(small, s, e) for s, e in zip(series, exact)]


def rotation_increment(omega, dt):
    """``exp(ω Δt)`` as a quaternion, ``(cos(wΔt/2), sin(wΔt/2) ω/w)``: the body's turn over Δt
    at a constant rate ω (exact, also at w = 0)."""
    ws = ca.fmax(ca.norm_2(omega), _TINY_RATE)
    half = ws * dt / 2
    return ca.vertcat(ca.cos(half), ca.sin(half) / ws * omega)


def propagate(q, b, P, omega_meas_B, dt, sigma_v, sigma_u):
    """One gyro sample: ``(q̂, β̂, P)`` at t + Δt from the measured rate over (t, t + Δt].

    ``P`` must be symmetric (the filter keeps it so). ``Φ P Φᵀ + Q`` is computed by blocks,
    ``P = [[A, B], [Bᵀ, C]]`` with ``Φ₂₁ = 0``, ``Φ₂₂ = E``: ``B' = Φ₁₁ B + Φ₁₂ C + Q₁₂``,
    ``A' = (Φ₁₁ A + Φ₁₂ Bᵀ) Φ₁₁ᵀ + (Φ₁₁ B + Φ₁₂ C) Φ₁₂ᵀ + Q₁₁`` (its upper triangle, mirrored),
    ``C' = C + Q₂₂``: the same matrix as the full product to round-off, exactly symmetric, at
    about a third of its operations (the filter's cost on every gyro sample, docs/loop.md)."""
    omega = omega_meas_B - b
    w = ca.norm_2(omega)
    dq = rotation_increment(omega, dt)
    q_next = quat_mult(q, dq)
    q_next = q_next / ca.norm_2(q_next)
    a1, a2, a3 = _coefficients(w, dt)
    W = skew(omega)
    W2 = ca.mtimes(W, W)
    E = ca.SX.eye(3)
    Phi11 = E - W * a1 + W2 * a2
    Phi12 = W * a2 - E * dt - W2 * a3
    qv = sigma_v**2 * dt + sigma_u**2 * dt**3 / 3
    qc = -(sigma_u**2) * dt**2 / 2
    qb = sigma_u**2 * dt
    A, B, C = P[0:3, 0:3], P[0:3, 3:6], P[3:6, 3:6]
    T = ca.mtimes(Phi11, A) + ca.mtimes(Phi12, B.T)
    B1 = ca.mtimes(Phi11, B) + ca.mtimes(Phi12, C)
    A1 = [[None] * 3 for _ in range(3)]
    for i in range(3):
        for j in range(i, 3):
            a = ca.dot(T[i, :].T, Phi11[j, :].T) + ca.dot(B1[i, :].T, Phi12[j, :].T)
            A1[i][j] = A1[j][i] = a + qv if i == j else a
    C1 = [[C[min(i, j), max(i, j)] + (qb if i == j else 0) for j in range(3)] for i in range(3)]
    B1 = B1 + qc * E
    top = ca.horzcat(ca.vertcat(*[ca.horzcat(*r) for r in A1]), B1)
    bottom = ca.horzcat(B1.T, ca.vertcat(*[ca.horzcat(*r) for r in C1]))
    return q_next, b, ca.vertcat(top, bottom)


def attitude_error(q_ref, q):
    """``δα`` with ``q = q_ref ⊗ δq(δα)``: ``2 vec/w`` of ``q_ref⁻¹ ⊗ q`` (ref frame components)."""
    d = quat_mult(quat_conj(q_ref), q)
    return 2 * d[1:4] / d[0]


def update(q, b, P, q_SN_meas, gate, q_SB, r, D=None, latency=0.0, q_latency=0.0, joseph=False, nis=False):
    """One star-tracker head: ``(q̂, β̂, P)`` after its measurement when ``gate`` is 1 (fresh and
    valid), unchanged when 0. ``r`` = (r_cross, r_cross, r_about) [rad].

    A measurement taken ``latency`` [s] ago is compared with the estimate carried back by the
    filter's own turn since then, ``D`` (quaternion, :func:`rotation_increment` accumulated):
    ``q̂_s = q̂ ⊗ D⁻¹``. Its error ``C_Dᵀ(δα − ε)`` holds the error of that turn,
    ``ε = −Δβ L − ∫η_v``: ``H = C_SB C_Dᵀ [E, L E]``, and the gyro noise over the latency,
    ``q_latency = σ_v² L + σ_u² L³/3`` [rad²], is measurement noise correlated with the state
    error (the same noise moved the attitude since the sample): ``Cov(Δx, v) = M = −[q_L Cᵀ; 0]``,
    ``K = (P Hᵀ + M)(H P Hᵀ + H M + Mᵀ Hᵀ + R)⁻¹``.

    Covariance: with this (optimal) gain the Joseph form with its cross terms,
    ``(E − KH) P (E − KH)ᵀ + K R Kᵀ − (E − KH) M Kᵀ − K Mᵀ (E − KH)ᵀ``, equals
    ``P − K (P Hᵀ + M)ᵀ`` (expand it with ``K S = P Hᵀ + M``); the filter uses the short form, its
    upper triangle mirrored (exactly symmetric, a fifth of the operations). ``joseph=True`` gives
    the Joseph form (the test's reference: the two agree to round-off). ``nis=True``: also the
    normalised innovation squared ``zᵀ S⁻¹ z`` (S the innovation's covariance, the matrix the
    gain inverts), appended to the returned tuple."""
    if D is None:
        q_s, C = q, dcm(q_SB)
        H = ca.horzcat(C, ca.SX.zeros(3, 3))
    else:
        q_s = quat_mult(q, quat_conj(D))
        C = ca.mtimes(dcm(q_SB), dcm(D).T)
        H = ca.horzcat(C, latency * C)
    q_SN_hat = quat_mult(q_s, q_SB)
    z = attitude_error(q_SN_hat, q_SN_meas)
    R = ca.diag(r**2) + q_latency * ca.SX.eye(3)
    # the gyro noise over the latency is in the state error too: Cov(Δx, v) = M = -[q_L Cᵀ; 0]
    M = ca.vertcat(-q_latency * C.T, ca.SX.zeros(3, 3))
    PHt = ca.mtimes(P, H.T) + M
    S_inv = inv3(ca.mtimes(H, PHt) + ca.mtimes(M.T, H.T) + R)
    K = ca.mtimes(PHt, S_inv)
    dx = ca.mtimes(K, z)
    dq = ca.vertcat(1.0, dx[0:3] / 2)
    q_new = quat_mult(q, dq / ca.norm_2(dq))
    q_new = q_new / ca.norm_2(q_new)
    if joseph:
        IKH = ca.SX.eye(6) - ca.mtimes(K, H)
        cross = ca.mtimes([IKH, M, K.T])  # the correlated noise's terms (zero without latency)
        P_new = ca.mtimes([IKH, P, IKH.T]) + ca.mtimes([K, R, K.T]) - cross - cross.T
        P_new = 0.5 * (P_new + P_new.T)
    else:
        rows = [[None] * 6 for _ in range(6)]
        for i in range(6):
            for j in range(i, 6):
                rows[i][j] = rows[j][i] = P[i, j] - ca.dot(K[i, :].T, PHt[j, :].T)
        P_new = ca.vertcat(*[ca.horzcat(*row) for row in rows])
    on = gate > 0.5
    out = ca.if_else(on, q_new, q), ca.if_else(on, b + dx[3:6], b), ca.if_else(on, P_new, P)
    return out + (ca.mtimes([z.T, S_inv, z]),) if nis else out


_REPORTS: dict = {}

#: the innovation gate when none is set (``[fdir] st_alpha`` absent): no NIS exceeds it
NO_GATE = 1.0e300


def FDI_STATE(n: int) -> dict:
    """The filter's fault detection memory (n heads): each head's last normalised innovation
    squared, its consecutive rejections, whether it is excluded; whether the gyro is declared
    failed; when (each head, then the gyro) [s, -1: not]; the filter's own time [s]."""
    return dict(nis=n, reject=n, excluded=n, gyro_fault=1, t_fdir=n + 1, t_filter=1)


def innovation_gate(X: dict, Pp: dict, i: int, n: int, nis) -> dict:
    """The chi-squared innovation gate of head ``i`` (issue 34 item 2b): its sample is rejected
    (no update) when ``nis > gate`` (the chi-squared(3) quantile of ``1 - st_alpha``) and no gyro
    fault is declared; after ``persist`` consecutive rejections the head is excluded when no
    other head is rejecting at the time, else (or with one head) the gyro is declared failed
    (the heads agree with each other, not with the propagation); once it is, samples are
    accepted again (the filter re-converges on the heads). Returns the memory's new fields and
    ``_reject``."""
    failed = X["gyro_fault"] > 0.5
    reject = ca.logic_and(nis > Pp["gate"], ca.logic_not(failed))
    count = ca.if_else(reject, X["reject"][i] + 1.0, 0.0)
    others = sum((X["reject"][j] > 0.5 for j in range(n) if j != i), ca.SX(0)) > 0.5 if n > 1 else ca.SX(1)
    declared = count >= Pp["persist"]
    head = ca.logic_and(declared, ca.logic_not(others))
    gyro = ca.logic_and(declared, others)
    t = X["t_filter"]
    pick = [ca.if_else(j == i, v, X[f][j]) for f, v in (("nis", nis), ("reject", count),
                                                       ("excluded", ca.fmax(X["excluded"][i], head))) for j in range(n)]
    t_fdir = [ca.if_else(ca.logic_and(head, X["t_fdir"][i] < 0), t, X["t_fdir"][i]) if j == i else X["t_fdir"][j]
              for j in range(n)]
    t_fdir.append(ca.if_else(ca.logic_and(gyro, ca.logic_not(failed)), t, X["t_fdir"][n]))
    return {"nis": ca.vertcat(*pick[:n]), "reject": ca.vertcat(*pick[n:2 * n]), "excluded": ca.vertcat(*pick[2 * n:]),
            "gyro_fault": ca.fmax(X["gyro_fault"], gyro), "t_fdir": ca.vertcat(*t_fdir), "_reject": reject}


class Mekf:
    """The MEKF of one gyro and one or more star-tracker heads, tuned from their tables.

    Parameters
    ----------
    table : stationbed.scene.MekfEstimator  ``[estimator]``: overrides and the initial covariance.
    gyro : RateGyro  The gyro it propagates with, one filter step per gyro sample.
    heads : list of StarTracker  The heads it updates with (their period a whole number of the
        gyro's); the mounting and noise it assumes are the heads' tables (knowledge).
    """

    def __init__(self, table, gyro: RateGyro, heads: list[StarTracker]):
        if not heads:
            raise ValueError("the MEKF needs at least one star-tracker head")
        self.table, self.gyro, self.heads = table, gyro, list(heads)
        self.dt = gyro.period
        #: head i has a new sample every ``every[i]`` filter steps
        self.every = [int(round(h.period / self.dt)) for h in heads]
        n = len(heads)
        #: per head, its latency in its own periods (samples in flight)
        self.delays = [h.entry.n_delay for h in heads]
        #: the filter's state: FILTER, then per head with latency the filter's own turn since
        #: each sample in flight (quaternions, oldest first)
        self.state = Layout(q_BN=4, bias_B=3, P=(6, 6), **{f"D_{i}": (4, d) for i, d in enumerate(self.delays) if d},
                            **FDI_STATE(n))
        self.param_layout = Layout(dt=1, sigma_v=1, sigma_u=1, **{f"q_SB_{i}": 4 for i in range(n)},
                                   **{f"r_{i}": 3 for i in range(n)}, **{f"latency_{i}": 1 for i in range(n)},
                                   gate=1, persist=1)
        #: one tick's input: the gyro's rate, then per head its output and whether it is new
        self.inputs = Layout(omega_B=3, **{f"q_SN_{i}": 4 for i in range(n)}, **{f"valid_{i}": 1 for i in range(n)},
                             **{f"fresh_{i}": 1 for i in range(n)})
        g = gyro.entry
        values = dict(dt=self.dt, sigma_v=table.sigma_v if table.sigma_v is not None else g.sigma_v,
                      sigma_u=table.sigma_u if table.sigma_u is not None else g.sigma_u,
                      gate=NO_GATE, persist=1.0)  # (the innovation gate: [fdir] st_alpha sets it, flight.py)
        for i, h in enumerate(heads):
            values[f"q_SB_{i}"] = h.entry.mounting()
            cross = table.nea_cross if table.nea_cross is not None else h.entry.nea_cross
            about = table.nea_about if table.nea_about is not None else h.entry.nea_about
            values[f"r_{i}"] = [cross, cross, about]
            values[f"latency_{i}"] = h.entry.latency
        if min(values["sigma_v"], min(min(values[f"r_{i}"]) for i in range(n))) <= 0:
            raise ValueError("the MEKF needs sigma_v > 0 and noise-equivalent angles > 0 (give estimator.sigma_v, "
                             "nea_cross and nea_about for noise-free sensors)")
        self.params = self.param_layout.pack(values)
        self._f = self._tick = self._alone = self._report = self._compiled = None
        self._records: dict = {}

    @classmethod
    def from_sensors(cls, table, sensors: list) -> "Mekf":
        """The filter a ``[estimator]`` table names among built sensors (its gyro and heads)."""
        gyros = [s for s in sensors if isinstance(s, RateGyro)]
        gyro = next(s for s in gyros if s.name == table.gyro) if table.gyro else gyros[0]
        heads = [s for s in sensors if isinstance(s, StarTracker)
                 and (table.star_trackers is None or s.name in table.star_trackers)]
        return cls(table, gyro, heads)

    def initial(self, q_BN_hat, bias_B_hat=(0.0, 0.0, 0.0)) -> np.ndarray:
        """Filter state at the start: the given estimates, ``P0 = diag(σ_att0² E, σ_bias0² E)``."""
        t = self.table
        P0 = np.diag([t.sigma_attitude0**2] * 3 + [t.sigma_bias0**2] * 3)
        q = np.asarray(q_BN_hat, dtype=float)
        lines = {f"D_{i}": np.tile([[1.0], [0.0], [0.0], [0.0]], (1, d)) for i, d in enumerate(self.delays) if d}
        n = len(self.heads)
        fdi = dict(nis=np.zeros(n), reject=np.zeros(n), excluded=np.zeros(n), gyro_fault=0.0, t_fdir=-np.ones(n + 1),
                   t_filter=0.0)
        return self.state.pack(q_BN=q / np.linalg.norm(q), bias_B=bias_B_hat, P=P0, **lines, **fdi)

    # -- the expressions ------------------------------------------------------------------
    def function(self) -> ca.Function:
        """``(xf, z, p) -> (xf_next, omega_hat_B)``: propagate over one gyro sample with
        ``z.omega_B``, then update with each fresh valid head; ω̂ = ω̃ - β̂ after the update.

        An MX function of SX pieces: each head's update is a casadi ``Switch`` on its gate
        (fresh and valid), so generated code runs an update only when there is one (an SX
        ``if_else`` computes both branches: 538 instructions to propagate, 677 per update). A tick
        without any head sample runs the propagation alone (no head switch: no copies)."""
        if self._f is None:
            n = len(self.heads)
            name = f"mekf_{n}" + "".join(f"_{d}" for d in self.delays if any(self.delays))
            S = self.state
            xf, z, p = S.symbol("xf"), self.inputs.symbol("z"), self.param_layout.symbol("p")
            X, Z, Pp = S.split(xf), self.inputs.split(z), self.param_layout.split(p)
            q, b, P = propagate(X["q_BN"], X["bias_B"], X["P"], Z["omega_B"], Pp["dt"], Pp["sigma_v"], Pp["sigma_u"])
            dq = rotation_increment(Z["omega_B"] - X["bias_B"], Pp["dt"])
            lines = {f"D_{i}": ca.horzcat(*[quat_mult(X[f"D_{i}"][:, j], dq) for j in range(d)])
                     for i, d in enumerate(self.delays) if d}
            kept = {f: X[f] for f in FDI_STATE(n)}
            kept["t_filter"] = X["t_filter"] + Pp["dt"]
            prop = ca.Function(f"{name}_propagate", [xf, z, p], [S.pack(q_BN=q, bias_B=b, P=P, **lines, **kept)],
                               {"cse": True})
            skip = ca.Function(f"{name}_skip", [xf, z, p], [xf])
            xm, zm, pm = S.symbol("xf", ca.MX), self.inputs.symbol("z", ca.MX), self.param_layout.symbol("p", ca.MX)
            x1 = prop(xm, zm, pm)
            news = []  # whether head i has something for the filter this tick
            for i, d in enumerate(self.delays):
                lat = Pp[f"latency_{i}"]
                extra = {}
                if d:  # the oldest sample in flight arrives now
                    extra = dict(D=X[f"D_{i}"][:, 0], latency=lat,
                                 q_latency=Pp["sigma_v"] ** 2 * lat + Pp["sigma_u"] ** 2 * lat**3 / 3)
                q, b, P, nis = update(X["q_BN"], X["bias_B"], X["P"], Z[f"q_SN_{i}"], 1.0, Pp[f"q_SB_{i}"], Pp[f"r_{i}"],
                                      **extra, nis=True)
                new = innovation_gate(X, Pp, i, n, nis)
                reject = new.pop("_reject")
                upd = ca.Function(f"{name}_update_{i}", [xf, z, p], [S.pack({**X, "q_BN": ca.if_else(reject, X["q_BN"], q),
                                                                              "bias_B": ca.if_else(reject, X["bias_B"], b),
                                                                              "P": ca.if_else(reject, X["P"], P), **new})],
                                  {"cse": True})
                gate = self.inputs.get(zm, f"valid_{i}") * self.inputs.get(zm, f"fresh_{i}") * (1 - S.get(xm, "excluded")[i])
                news.append(self.inputs.get(zm, f"fresh_{i}") if d else gate)
                x1 = ca.Function.if_else(f"{name}_head_{i}", upd, skip)(gate, x1, zm, pm)
                if d:  # a new sample leaves the head now: its turn starts at identity
                    shifted = ca.horzcat(X[f"D_{i}"][:, 1:], ca.DM([1.0, 0.0, 0.0, 0.0]))
                    shift = ca.Function(f"{name}_shift_{i}", [xf, z, p], [S.pack({**X, f"D_{i}": shifted})])
                    x1 = ca.Function.if_else(f"{name}_sample_{i}", shift, skip)(self.inputs.get(zm, f"fresh_{i}"),
                                                                               x1, zm, pm)
            # most ticks have no head sample: then the propagation alone, with no head's switch
            # (each would copy the state through its skip branch)
            heads = ca.Function(f"{name}_heads", [xm, zm, pm], [x1, self.inputs.get(zm, "omega_B") - S.get(x1, "bias_B")])
            wm = ca.MX.sym("omega_hat_prev", 3)
            omega = self.inputs.get(z, "omega_B")
            xp = prop(xf, z, p)
            # the tick's three cases as one switch (its case computed once, in MX), each writing the
            # filter's state and ω̂ straight to the caller: 0 no gyro sample (both held), 1 the
            # propagation alone (SX: no copy of the state between it and ω̂), 2 with the heads
            hold = ca.Function(f"{name}_hold", [xm, wm, zm, pm], [xm, wm])
            alone = ca.Function(f"{name}_alone", [xf, ca.SX.sym("omega_hat_prev", 3), z, p], [xp, omega - S.get(xp, "bias_B")],
                                {"cse": True})
            self._alone = alone
            with_heads = ca.Function(f"{name}_with_heads", [xm, wm, zm, pm], heads(xm, zm, pm))
            cases = ca.Function.conditional(f"{name}_cases", [hold, alone, with_heads], hold)
            due = ca.MX.sym("due")
            case = due * (1 + (sum(news[1:], news[0]) > 0.5))
            self._tick = ca.Function(f"{name}_tick", [due, xm, wm, zm, pm], cases(case, xm, wm, zm, pm),
                                     ["due", "xf", "omega_hat_prev", "z", "p"], ["xf_next", "omega_hat_B"],
                                     {"always_inline": True})
            x1, omega_hat = cases(1 + (sum(news[1:], news[0]) > 0.5), xm, ca.MX.zeros(3), zm, pm)
            # inlined where it is called: no copy of the state at the call
            self._f = ca.Function(name, [xm, zm, pm], [x1, omega_hat], ["xf", "z", "p"], ["xf_next", "omega_hat_B"],
                                  {"always_inline": True})
        return self._f

    def alone_function(self) -> ca.Function:
        """``(xf, omega_hat_prev, z, p) -> (xf_next, omega_hat_B)`` as an SX function: the tick
        of a gyro sample without a head's (the propagation alone; the middle case of
        :meth:`tick_function`), for a caller that knows no head has a sample."""
        self.function()
        return self._alone

    def tick_function(self) -> ca.Function:
        """``(due, xf, omega_hat_prev, z, p) -> (xf_next, omega_hat_B)``: :meth:`function` on a
        tick where the gyro has a sample (``due`` 1), both held where it has none (the suite's
        tick; one switch: see :meth:`function`)."""
        self.function()
        return self._tick

    def compiled(self) -> ca.Function:
        """:meth:`function` generated as C (cached on disk; casadi's evaluator without a compiler)."""
        if self._compiled is None:
            f, r = self.function(), self.report_function()
            lib = compile_functions([f, r], f.name())
            self._compiled = lib[f.name()]
            self._report_compiled = lib[r.name()]
        return self._compiled

    def report_function(self) -> ca.Function:
        """``(xf, q_BN, bias_B) -> (err_B, sigma3, nees)`` against the truth: the attitude error
        δα [rad] (B, ``q = q̂ ⊗ δq(δα)``), three standard deviations of the six error states
        (rad, rad/s) and ``Δxᵀ P⁻¹ Δx``."""
        if self._report is None:
            self._report = _REPORTS.get(self.state)
        if self._report is None:  # one per state layout (a Monte Carlo's runs share it)
            xf, q, b = self.state.symbol("xf"), ca.SX.sym("q_BN", 4), ca.SX.sym("bias_B", 3)
            X = self.state.split(xf)
            dx = ca.vertcat(attitude_error(X["q_BN"], q), b - X["bias_B"])
            nees = ca.mtimes(dx.T, ca.solve(X["P"], dx))
            self._report = ca.Function("mekf_report", [xf, q, b], [dx[0:3], 3 * ca.sqrt(ca.diag(X["P"])), nees],
                                       ["xf", "q_BN", "bias_B"], ["err_B", "sigma3", "nees"])
            _REPORTS[self.state] = self._report
        return self._report

    # -- numbers --------------------------------------------------------------------------
    def record(self, xf0: np.ndarray, z: np.ndarray, f: ca.Function | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Filter states after each of N ticks, shape (N, state.size), and ω̂ (N, 3), in one
        call (``mapaccum`` of ``f``, default :meth:`compiled`); ``z`` has shape (N, inputs.size)."""
        z = np.atleast_2d(np.asarray(z, dtype=float))
        if z.shape[1] != self.inputs.size or np.shape(xf0) != (self.state.size,):
            raise ValueError(f"MEKF record: z has shape {z.shape}, expected (N, {self.inputs.size}); "
                             f"xf0 {np.shape(xf0)}, expected ({self.state.size},)")
        n = z.shape[0]
        f = f or self.compiled()
        fc = self._records.get((id(f), n))
        if fc is None:  # buffers bound once: a (k, n) input is the (n, k) table's numbers in order
            fc = self._records[(id(f), n)] = FastCall(f.mapaccum(f"mekf_record_{n}", n))
        for arg, value in zip(fc.args, (xf0, z, np.tile(self.params, n))):
            arg[:] = np.ravel(value)
        fc()
        return fc.res[0].reshape(n, -1).copy(), fc.res[1].reshape(n, -1).copy()

    def report(self, xf: np.ndarray, q_BN: np.ndarray, bias_B: np.ndarray):
        """:meth:`report_function` over N rows: ``err_B`` (N, 3), ``sigma3`` (N, 6), ``nees`` (N,)."""
        n = len(xf)
        self.compiled()
        fc = self._records.get(("report", n))
        if fc is None:
            fc = self._records[("report", n)] = FastCall(self._report_compiled.map(n))
        for arg, value in zip(fc.args, (xf, q_BN, bias_B)):
            arg[:] = np.ravel(value)
        fc()
        return fc.res[0].reshape(n, 3).copy(), fc.res[1].reshape(n, 6).copy(), fc.res[2].copy()
