"""Loop analysis of a scene's controller at an operating point.

The controller's command is a function of the measurement, which is a function of the plant
state: ``v = k(t, meas(t, x(z)))``. Its Jacobian ``K = ∂v/∂z`` at the operating point closes the
loop ``ż = A z + B_v v`` at the plant input: exact (casadi, through the same ``meas`` function the
simulator compiles) for a law with a symbolic form (``Controller.symbolic``); for a law written
in Python only, by central differences of its ``_update`` on the same measurement
(:func:`numerical_gain`: step ``h_j = FD_REL max(|z_j|, 1)`` per state, in its SI unit). The
loop is the law on the *truth*: a scene's sensors, estimator and measurement delay are not in it
(:func:`left_out` names them; ``margins`` prints them).

Per input channel i the loop is broken there with the other channels closed:
``L_i(s) = -K_i (sI - A - B_o K_o)⁻¹ B_i`` (negative-feedback convention), and python-control gives
its gain, phase and disk margins (``stability_margins``, ``disk_margins``), the bandwidth of
``T_i = L_i / (1 + L_i)`` (``bandwidth``: -3 dB) and the peak of ``|S_i| = |1 / (1 + L_i)|``.
The zero-order hold of the controller period is not in these loops (its half-period delay costs
``ω T / 2`` rad of phase at ω; 0.03 deg at 0.005 rad/s and 10 Hz).

A structural mode inside the control bandwidth is flagged: an array mode's open-loop pole pair
(:func:`~.plant.modal_poles`) below the largest channel bandwidth.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from ..run.closed_loop import plant_facts
from ..run.laws import build_controller
from ..run.system import build_system
from ..model import Structure
from ..model.environment import q_ON
from ..core.paths import safe_name
from ..core.rotation import quat_mult
from ..run.controller import command_values
from .plant import _default_z0, linearization, modal_poles, plant_functions

__all__ = ["LoopAnalysis", "loop_analysis", "loop_margins", "settling_time", "frequency_grid", "gain_crossings",
           "numerical_gain", "left_out"]

#: Central differences' relative step: ε^(1/3) (ε = 2.2e-16) balances their truncation error
#: (~h² |v‴| / 6) against round-off (~ε |v| / h); a step ``FD_REL max(|z_j|, 1)`` in each state's
#: SI unit (rad, rad/s, N m s) leaves K ~1e-10 relative off for a smooth law.
FD_REL = float(np.finfo(float).eps ** (1.0 / 3.0))
#: An entry of A or K is structurally zero when below this fraction of its row's largest entry
#: (the steering law cancels the gimbal angles' effect on the body to ~1e-17 relative: round-off).
STRUCTURAL_ZERO = 1e-12


def frequency_grid(A) -> np.ndarray:
    """A log grid [rad/s] three decades either side of the nonzero |eigenvalues| of ``A``."""
    lam = np.abs(np.linalg.eigvals(A))
    lam = lam[lam > 1e-12]
    lo, hi = (lam.min(), lam.max()) if lam.size else (1e-6, 1.0)
    return np.logspace(np.log10(lo) - 3, np.log10(hi) + 3, 3000)


def _response(A, B, C, s) -> complex:
    """``C (sI - A)⁻¹ B`` of a SISO state-space loop at the complex frequency ``s``."""
    return complex((C @ np.linalg.solve(s * np.eye(A.shape[0]) - A, B)).item())


def _responses(A, B, C, s) -> np.ndarray:
    """:func:`_response` at every complex frequency of ``s`` (1-D), in one stacked solve (the
    same LAPACK solve per frequency; a Monte Carlo designs a law per sample, issue 22)."""
    n = A.shape[0]
    S = s[:, None, None] * np.eye(n) - A
    X = np.linalg.solve(S, np.broadcast_to(B.reshape(n, -1), (len(s), n, B.reshape(n, -1).shape[1])))
    return np.matmul(C.reshape(1, n), X)[:, 0, 0]


def _crossing_grid(A) -> np.ndarray:
    """:func:`frequency_grid` with each lightly damped pole's neighbourhood sampled densely (a
    pole turns the phase within ~|Re| of its frequency)."""
    w = frequency_grid(A)
    poles = np.linalg.eigvals(A)
    dense = [p.imag + max(abs(p.real), 1e-6 * p.imag) * np.linspace(-20.0, 20.0, 81) for p in poles if p.imag > 0]
    w = np.unique(np.concatenate([w] + dense))
    return w[w > 0]


def gain_crossings(L, response=None) -> list[tuple[float, float]]:
    """The gains at which the loop ``L`` (negative feedback) puts a closed-loop pole on the
    imaginary axis: ``1 + k L(jω) = 0`` with ``k > 0``, i.e. every ``ω`` where ``L(jω)`` is real
    and negative, ``k = -1 / L(jω)``. Returns ``(k, ω)`` pairs [-, rad/s], ω = 0 included.

    ``L(jω)`` is evaluated from the state-space matrices directly (no transfer-function
    polynomials: a loop with structurally zero poles, e.g. sun-tracking joints at rest, made
    python-control's ``stability_margins`` divide 0 by 0 at ω = 0, drop that crossing and warn).
    ω = 0: ``L(0⁺)`` at ``s`` six decades below :func:`frequency_grid` (the limit, as the poles
    at exactly 0 are uncontrollable or unobservable); ω > 0: sign changes of ``Im L(jω)`` on the
    grid, refined by Brent's method. ``response``: ``(w, L(jw))`` on :func:`_crossing_grid`
    already computed (:func:`loop_margins` reuses it).
    """
    from scipy.optimize import brentq

    A, B, C = (np.asarray(M, float) for M in (L.A, L.B, L.C))
    w, Lw = response if response is not None else (_crossing_grid(A), None)
    out = []
    L0 = _response(A, B, C, w[0] * 1e-6)  # real s: L(0⁺) is real
    if math.isfinite(L0.real) and L0.real < 0.0:
        out.append((-1.0 / L0.real, 0.0))
    im = (_responses(A, B, C, 1j * w) if Lw is None else Lw).imag
    for i in np.nonzero(np.sign(im[:-1]) * np.sign(im[1:]) < 0)[0]:
        wc = brentq(lambda x: _response(A, B, C, 1j * x).imag, w[i], w[i + 1], xtol=1e-14 * w[i], rtol=1e-12)
        r = _response(A, B, C, 1j * wc)
        if r.real < 0.0 and abs(r.imag) <= 1e-6 * abs(r):  # a crossing, not a pole (|L| -> inf)
            out.append((-1.0 / r.real, float(wc)))
    return out


def siso_margins(L, response=None) -> dict:
    """Gain and phase margins of a SISO loop (negative feedback).

    The gain interval ``(gain_margin_down, gain_margin_up)``: the loop closed as ``1 + k L``
    keeps its nominal (k = 1) stability for every gain inside it; the bounds are the crossings of
    :func:`gain_crossings` nearest to 1 below and above (0 / inf when none). A plant that gravity
    gradient makes unstable has a *lower* gain margin (often at ω = 0). The phase margin [deg]
    and its crossover [rad/s] over all gain crossovers are python-control's
    (``stability_margins(L, returnall=True)``; its own gain-margin search, which misses the ω = 0
    crossing of such loops, is not used, and its 0/0 warnings there are silenced); the phase
    crossover [rad/s] is that of the upper bound."""
    import control

    with np.errstate(invalid="ignore", divide="ignore"):
        _, pm, _, _, wgc, _ = control.stability_margins(L, returnall=True)
    pm, wgc = np.atleast_1d(np.asarray(pm, float)), np.atleast_1d(np.asarray(wgc, float))
    ok = np.nonzero(np.isfinite(pm))[0]
    k = ok[np.argmin(np.abs(pm[ok]))] if ok.size else None
    cross = gain_crossings(L, response)
    below = [c for c in cross if c[0] < 1.0]
    above = [c for c in cross if c[0] > 1.0]
    lo = max(below) if below else (0.0, math.nan)
    hi = min(above) if above else (math.inf, math.nan)
    return {
        "gain_margin_up": float(hi[0]),
        "gain_margin_down": float(lo[0]),
        "phase_margin_deg": float(abs(pm[k])) if k is not None else math.inf,
        "crossover_rad_s": float(wgc[k]) if k is not None and wgc.size == pm.size else math.nan,
        "phase_crossover_rad_s": float(hi[1]),
        "phase_crossover_down_rad_s": float(lo[1]),
    }


def loop_margins(A, B, K) -> list[dict]:
    """Per input channel i: margins of the loop broken at that input, the others closed.

    ``u = -K x`` (the LQR convention): ``L_i(s) = K_i (sI - A + B_j K_j)⁻¹ B_i`` (j ≠ i).
    python-control's ``stability_margins(..., returnall=True)`` gives every crossing; reported: the
    smallest upward gain margin (> 1; inf when none), the largest downward gain margin (< 1; 0
    when none: LQR guarantees ≤ 1/2), the smallest phase margin [deg] (LQR guarantees ≥ 60 deg),
    its crossover [rad/s], and the stability margin ``min_ω |1 + L(jω)|`` (LQR guarantees ≥ 1:
    Kalman's return-difference inequality) on :func:`frequency_grid`.
    """
    import control

    out = []
    m = B.shape[1]
    for i in range(m):
        others = [j for j in range(m) if j != i]
        Ai = A - B[:, others] @ K[others, :]
        L = control.ss(Ai, B[:, [i]], K[[i], :], np.zeros((1, 1)))
        # one stacked solve for both: the crossing grid holds frequency_grid's points exactly,
        # and each frequency's solve is its own (the same values as two solves)
        wc = _crossing_grid(Ai)
        Lc = _responses(Ai, B[:, i], K[i], 1j * wc)
        mg = siso_margins(L, (wc, Lc))
        Lw = Lc[np.searchsorted(wc, frequency_grid(Ai))]
        out.append({**mg, "stability_margin": float(np.abs(1.0 + Lw).min())})
    return out


def loop_states(A, K) -> np.ndarray:
    """Indices of the states the loop sees: those K reads and, recursively, those that drive them
    through A (the rest, e.g. gimbal angles behind an exact steering law, are unobservable from the
    command and only add cancelling poles at the origin)."""
    def nz(M):
        scale = np.abs(M).max(axis=1, keepdims=True)
        return np.abs(M) > STRUCTURAL_ZERO * np.where(scale > 0, scale, 1.0)

    KA, AA = nz(K), nz(A)
    keep = KA.any(axis=0)
    while True:
        more = keep | AA[keep].any(axis=0)
        if (more == keep).all():
            return np.nonzero(keep)[0]
        keep = more


def settling_time(poles) -> float:
    """``4 / |Re(slowest pole)|`` [s]: the 2 % settling time of the slowest mode (e⁻⁴ ≈ 1.8 %)."""
    slow = float(np.min(np.abs(np.real(np.asarray(poles)))))
    return math.inf if slow == 0 else 4.0 / slow


@dataclass
class LoopAnalysis:
    """The loop of a scene's controller at its operating point.

    ``plant``: the linear plant (control.StateSpace, named); ``K``: ``∂v/∂z`` (n_v, n_z);
    ``closed``: ``ż = (A + B_v K) z + B_d d`` with outputs the plant's (named);
    ``loops``: per channel the SISO ``L_i`` (control.StateSpace); ``channels``: per channel a dict
    of margins; ``poles``: closed-loop poles [rad/s]; ``structural_in_band``: flagged modes.
    """

    plant: object
    K: np.ndarray
    closed: object
    loops: list
    channels: list
    poles: np.ndarray
    open_poles: np.ndarray
    structural_in_band: list = field(default_factory=list)
    controller: object = None
    loop_states: list = field(default_factory=list)  # the states the per-channel loops keep
    pole_states: list = field(default_factory=list)  # per pole: the state its eigenvector is largest in
    gain: str = "symbolic"  # how K was taken: "symbolic" (exact) or "numerical" (central differences)
    left_out: list = field(default_factory=list)  # what the scene flies that the loop leaves out (:func:`left_out`)


def _reference_RO(scene, q_ref, t):
    """``q_RO``: a law's reference ``q_ref`` (relative to N; None: N itself) relative to LVLH at
    ``t`` (relative to N without an orbit), scalar part >= 0."""
    if q_ref is None:
        return np.array([1.0, 0.0, 0.0, 0.0])
    q_ref = np.asarray(q_ref, float).ravel()
    if scene.orbit is None:
        return q_ref
    o = scene.orbit
    qo = np.asarray(q_ON(o.u0 + o.mean_motion * t, o.inclination), float).ravel()
    r = np.asarray(quat_mult(np.array([qo[0], -qo[1], -qo[2], -qo[3]]), q_ref), float).ravel()
    return r if r[0] >= 0 else -r


def _symbolic_law(ctrl, pf, p, t):
    """``(v(z, q_RO), q_ref(z, q_RO))`` of a law with a symbolic form, and ``K(z, q_RO)``: its
    exact Jacobian ``∂v/∂z`` (casadi), through the compiled measurement function."""
    z, q_RO = ca.SX.sym("z", pf["nz"]), ca.SX.sym("q_RO", 4)
    cp = ca.DM(np.asarray(ctrl.symbolic_params(), float))
    y = pf["system"].sx["meas"](t, pf["x_of_z"](t, z, q_RO, ca.DM(p)), ca.DM(p))
    cmd, q_ref = ctrl.symbolic(ca.SX(t), y, cp)
    cmd = ca.vertcat(cmd)
    q_ref = ca.DM([1.0, 0.0, 0.0, 0.0]) if q_ref is None else q_ref
    f = ca.Function("law", [z, q_RO], [cmd, ca.jacobian(cmd, z), ca.vertcat(q_ref)])
    return lambda zv, qv: tuple(np.array(m) for m in f(zv, qv))  # (v, K, q_ref)


def numerical_gain(law, z0, step=None):
    """``K = ∂v/∂z`` of ``v = law(z)`` at ``z0`` by central differences, (n_v, n_z).

    ``step`` (n_z,): per state [its SI unit]; default ``FD_REL max(|z0_j|, 1)``
    (:data:`FD_REL`). Each column ``(v(z0 + h e_j) - v(z0 - h e_j)) / 2h``: truncation error
    ``h² ∂³v/∂z_j³ / 6``, round-off ``~ε |v| / h``."""
    z0 = np.asarray(z0, float)
    h = FD_REL * np.maximum(np.abs(z0), 1.0) if step is None else np.asarray(step, float)
    cols = []
    for j in range(z0.size):
        e = np.zeros(z0.size)
        e[j] = h[j]
        cols.append((np.asarray(law(z0 + e), float) - np.asarray(law(z0 - e), float)) / (2.0 * h[j]))
    return np.column_stack(cols)


def _python_law(ctrl, pf, p, t):
    """``law(z, q_RO) -> (v, q_ref_BN)``: the controller's ``update`` at ``t`` on the compiled
    measurement of the plant state ``x(z)``, each call on a fresh copy of the law as reset (a
    law that keeps numbers between ticks is differentiated at its state after ``reset``); a law
    that cannot be copied (an FMU's instance) is called in place (:func:`loop_analysis` then
    checks that its command at the point did not change)."""
    from ..run.controller import Measurement, measurement_fields

    model = pf["model"]
    lay = measurement_fields(0 if model.cmg is None else model.cmg.n_gimbals, model.structure.n_app)
    meas, fx = pf["system"].sx["meas"], pf["x_of_z"]
    keep = {id(ctrl.plant): ctrl.plant}  # the plant facts (casadi Functions) are shared, not copied
    try:
        copy.deepcopy(ctrl, dict(keep))
        fresh = True
    except Exception:  # noqa: BLE001 - e.g. an FMU instance (a lock, a shared library)
        fresh = False

    def law(z, q_RO):
        c = copy.deepcopy(ctrl, dict(keep)) if fresh else ctrl
        m = Measurement(np.array(meas(t, fx(t, z, q_RO, p), p), float).ravel(), lay)
        m.t = t
        v = command_values(c.update(t, m), len(pf["controls"]), c.command)
        return v, c.q_ref_BN

    return law


def left_out(scene) -> list[str]:
    """What the scene flies between the truth and the law that the loop analysis leaves out
    (the loop is the law on the true state): its ``[[sensor]]`` entries by kind, ``[estimator]``
    and the ideal measurement's delay and noise, one phrase each (empty when the law flies on the
    truth): their sampling, noise, filter dynamics and delay are not in the margins."""
    out = []
    kinds: dict = {}
    for s in scene.sensor:
        kinds.setdefault(s.kind, []).append(s.name)
    for kind, names in kinds.items():
        out.append(f"{kind} {', '.join(names)}")
    if scene.estimator is not None:
        out.append(f"estimator {scene.estimator.kind}")
    sens = scene.controller.sensor if scene.controller is not None else None
    if sens is not None and sens.delay > 0:
        out.append(f"controller.sensor.delay = {sens.delay:g} s")
    if sens is not None and (sens.attitude_noise > 0 or sens.rate_noise > 0):
        out.append("controller.sensor noise")
    return out


def loop_analysis(scene, controller=None, *, t: float = 0.0, gain: str = "auto") -> LoopAnalysis:
    """Linearise the scene's plant and its controller and analyse the loop.

    Parameters
    ----------
    scene : Scene  With a ``[controller]`` (or pass ``controller``).
    controller : Controller, optional  An instance (reset here on the scene's plant facts).
    t : float  The instant the time-varying terms are frozen at [s]; the sun-tracking joints are
        on their tracking state at t (:func:`~.plant.linearization`).
    gain : "auto", "symbolic" or "numerical"  How ``K = ∂v/∂z`` is taken: exactly from the law's
        ``symbolic`` form, or by central differences of its ``_update`` (:func:`numerical_gain`);
        "auto": symbolic when the law has one.
    """
    import control

    if controller is None:
        spec = scene.controller
        if spec is None:
            raise ValueError("margins: the scene has no [controller]")
        controller = build_controller(spec, base_dir=scene.folder)
    if gain not in ("auto", "symbolic", "numerical"):
        raise ValueError(f"gain = {gain!r}: expected 'auto', 'symbolic' or 'numerical'")
    has_symbolic = callable(getattr(controller, "symbolic", None))
    if gain == "symbolic" and not has_symbolic:
        raise ValueError(f"margins: controller '{controller.name}' has no symbolic form (Controller.symbolic)")
    numerical = gain == "numerical" or not has_symbolic
    if callable(getattr(controller, "symbolic_state", None)):  # (run/law_state.py)
        raise ValueError(f"margins: controller '{controller.name}' keeps a state between ticks (symbolic_state): "
                         "the loop analysis closes a stateless law only (its own design reports its margins)")
    command = controller.command
    system = build_system(Structure.of(scene), scene.simulation.formulation, scene.simulation.integrator)
    model = system.formulation.model
    p = model.params(scene)
    controller.reset(plant_facts(scene, system, controller.period))  # the law designs on knowledge
    pf = plant_functions(scene, command)
    identity = np.array([1.0, 0.0, 0.0, 0.0])
    if numerical:
        law = _python_law(controller, pf, p, t)
        q_RO = _reference_RO(scene, law(_default_z0(scene, pf, p, t, identity), identity)[1], t)
        z0 = _default_z0(scene, pf, p, t, q_RO)  # the joints tracking at t, seen from the reference
        v0 = law(z0, q_RO)[0]
        K = numerical_gain(lambda z: law(z, q_RO)[0], z0)
        if not np.array_equal(law(z0, q_RO)[0], v0):
            raise ValueError(f"margins: controller '{controller.name}' gave another command at the same state on a later "
                             "call: it keeps a state between ticks (the loop analysis linearises a stateless law)")
    else:
        law = _symbolic_law(controller, pf, p, t)
        q_RO = _reference_RO(scene, law(_default_z0(scene, pf, p, t, identity), identity)[2], t)
        z0 = _default_z0(scene, pf, p, t, q_RO)
        v0, K, _ = law(z0, q_RO)
    if not np.any(K):
        raise ValueError(f"margins: controller '{controller.name}' does not feed back the state at t = {t:g} s "
                         "(∂command/∂state = 0): there is no loop to break")
    lin = linearization(scene, "lvlh", t=t, q_ref=q_RO, command=command, v0=v0)
    P = lin.ss
    nv = len(pf["controls"])
    A, Bv, Bd, C = P.A, P.B[:, :nv], P.B[:, nv:], P.C
    Acl = A + Bv @ K
    closed = control.ss(Acl, Bd, C, np.zeros((C.shape[0], Bd.shape[1])), states=pf["states"], inputs=pf["disturbances"],
                        outputs=pf["outputs"], name=f"{safe_name(scene.name)}_closed_loop")
    loops, channels = [], []
    keep = loop_states(A, K)
    Ak, Bk, Kk = A[np.ix_(keep, keep)], Bv[keep], K[:, keep]
    w = frequency_grid(Ak + Bk @ Kk)
    for i in range(nv):
        others = [j for j in range(nv) if j != i]
        Ai = Ak + Bk[:, others] @ Kk[others, :]
        L = control.ss(Ai, Bk[:, [i]], -Kk[[i], :], np.zeros((1, 1)), inputs=[pf["controls"][i]], outputs=[pf["controls"][i]],
                       name=f"L_{pf['controls'][i]}")
        loops.append(L)
        mg = siso_margins(L)
        dm, dgm, dpm = control.disk_margins(L, w)
        Lw = np.asarray(L(1j * w)).ravel()
        S = 1.0 / (1.0 + Lw)
        T = Lw / (1.0 + Lw)
        # bandwidth: the first frequency where |T| falls 3 dB below its low-frequency value
        t0 = abs(T[0])
        below = np.nonzero(np.abs(T) < t0 / math.sqrt(2.0))[0]
        bw = float(w[below[0]]) if below.size and t0 > 0 else math.nan
        channels.append({
            "channel": pf["controls"][i],
            **mg, "disk_margin": float(dm), "disk_gain_margin": float(dgm),
            "disk_phase_margin_deg": float(dpm), "bandwidth_rad_s": bw,
            "sensitivity_peak": float(np.abs(S).max()), "sensitivity_peak_rad_s": float(w[np.argmax(np.abs(S))]),
        })
    open_poles = np.linalg.eigvals(A)
    bw_max = max((c["bandwidth_rad_s"] for c in channels if math.isfinite(c["bandwidth_rad_s"])), default=0.0)
    flagged = [float(abs(m)) for m in modal_poles(A, lin.modal_states) if m.imag > 0 and abs(m) < bw_max]
    # A[keep, drop] = 0 (structurally): the closed loop is block triangular, its poles those of the
    # two diagonal blocks (computed apart: the repeated zero poles of the dropped states, e.g. gimbal
    # angles, would otherwise split by round-off into ±ε^(1/k) pairs)
    drop = np.setdiff1d(np.arange(A.shape[0]), keep)
    poles, where = [], []
    for idx in (keep, drop):
        if idx.size:
            lam, vec = np.linalg.eig(Acl[np.ix_(idx, idx)])
            poles += list(lam)
            where += [pf["states"][idx[int(np.argmax(np.abs(v)))]] for v in vec.T]
    poles = np.array(poles)
    return LoopAnalysis(P, K, closed, loops, channels, poles, open_poles, flagged, controller,
                        [pf["states"][j] for j in keep], where, "numerical" if numerical else "symbolic", left_out(scene))
