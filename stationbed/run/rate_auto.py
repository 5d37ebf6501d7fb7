"""The default environment rate (issue 25): ``[simulation] environment_rate = "auto"`` picks the
largest block of ticks whose proven bound (:func:`~.rates.hold_bound_rad`) on the attitude
difference from the every-stage evaluation stays inside :data:`TARGET_RAD`
(docs/design.md "Effects at their own rate").

The bound needs the loop's shape and the environment torque's rates:

* the loop: a ``pd`` law's ``bandwidth`` (ω_n) and ``damping`` (ζ, below 1: the bound's impulse
  response is the underdamped one) and the body's smallest principal inertia (the arrays only add
  inertia, and the bound falls as 1/I, so the body's is the conservative one);
* the torque: ``M1``, ``M2`` and the penumbra stretches (:func:`~.rates.torque_rates`) from a
  *probe*: the same scene flown every stage with a 1 s tick, rows at 1 s, noise off, over
  ``min(duration, one orbit)``. The environment torque moves at orbital rate (the orbit, the sun,
  the arrays' tracking); the probe's coarser tick moves the attitude it acts on by the loop's
  tracking error only, a second-order change of the rates. It costs ~0.06 s of CPU and is kept
  per scene content: in the process (the last :data:`KEEP`) and on disk in the compile cache's
  ``rates`` folder (keyed by the scene and stationbed's source files), so a scene flown again,
  in this process or another, does not pay it twice.

A loop flown on ``[[sensor]]`` tables and the MEKF (issue 20) takes the same choice: the filter is
kinematic (it propagates with the gyro, never with a torque model), so its estimation error does
not depend on the environment torque to first order (the separation of estimation and control),
and the law on the estimate moves the truth's attitude through the same PD loop as the truth-fed
law; the probe flies the scene truth-fed (sensors and estimator off: the environment torque is
the same to the tracking error). docs/design.md "Effects at their own rate" argues it in full.

Where the loop cannot honour a rate (thrusters: their fused executor evaluates every stage) or
the bound's assumptions do not hold (a law other than ``pd``, ζ >= 1, no
environment torque), ``auto`` is every stage (0) and :func:`auto_choice` says why.
"""

from __future__ import annotations

import hashlib
import importlib
import inspect
import json
import logging
import math
import os
from collections import OrderedDict
from pathlib import Path

import numpy as np

from ..core.compile import cache_dir
from ..core.progress import LOGGER

__all__ = ["AUTO", "TARGET_RAD", "CANDIDATES", "choice", "auto_choice", "scene_choice", "set_runner", "g_norms",
           "hold_bound_rad", "torque_rates"]

AUTO = "auto"
#: the issue's accuracy: attitude difference from the every-stage evaluation per orbit [rad]
TARGET_RAD = 1e-6
#: the rates auto may pick (ticks per evaluation): few, so few compiled structures
CANDIDATES = (100, 50, 20, 10, 5, 2, 1)
#: the probe's tick and row [s]: orbital-rate torques, sampled finer than the penumbra (~10 s)
PROBE_DT_S = 1.0
#: probes kept (scene content -> choice)
KEEP = 16

_CHOICES: OrderedDict[str, dict] = OrderedDict()
_BY_ID: OrderedDict[int, tuple] = OrderedDict()
_RUN = None  # simulate(scene, keep=...), registered by run/simulation.py (it builds the loops that ask)


def set_runner(run) -> None:
    """Register ``simulate`` as the probe's runner (called once by :mod:`.simulation`)."""
    global _RUN
    _RUN = run


def _why_not(scene, params, thrust: bool, flight: bool) -> str | None:
    """Why ``auto`` is every stage (None: the bound applies)."""
    if thrust:
        return "thrusters: their fused loop evaluates the environment every stage"
    # [[sensor]] tables (``flight``): the composed loop honours the rate (its env block) and the
    # bound holds on the estimate's loop (module docstring)
    if scene.controller is None or scene.controller.name != "pd" or not (hasattr(params, "bandwidth")
                                                                          and hasattr(params, "damping")):
        return "the bound is proven for the pd law's loop shape"
    if not 0.0 < float(params.damping) < 1.0:
        return "the bound needs an underdamped loop (pd damping < 1)"
    if scene.orbit is None:
        return "no orbit"
    return None


class _Quiet(logging.Filter):
    def filter(self, record: logging.LogRecord) -> bool:
        return False


def _probe_scene(scene):
    """The probe's scene: ``scene`` flown every stage on the truth (no sensors, no estimator: the
    same torque) with a 1 s tick and rows, by RK4 (a DOP853 scene's too: the torque, not the
    steps), over ``min(duration, one orbit)``, without the scheduled faults. The choice is kept per this scene, so samples
    that differ only in what the probe drops (a sensor seed) share one probe."""
    dur = min(scene.simulation.duration, 2.0 * math.pi / scene.orbit.mean_motion)
    return scene.replace({"simulation.environment_rate": 0, "controller.period": PROBE_DT_S, "simulation.step": PROBE_DT_S,
                          "simulation.integrator": "rk4", "simulation.output_dt": PROBE_DT_S,
                          "simulation.duration": max(dur, 3.0 * PROBE_DT_S),
                          "controller.sensor": {}, "sensor": [], "estimator": None,
                          "fault": []})  # (a fault's time may be off the probe's 1 s grid; the probe's
    # run shares the compiled calls' buffers with the run that asks: its p must stay the nominal)


def _probe(probe_scene) -> tuple[float, float, list]:
    """``(M1, M2, fast)`` of the environment torque from the 1 s every-stage probe of
    :func:`_probe_scene`'s scene."""
    if _RUN is None:  # run/simulation.py registers simulate when imported (it imports this module)
        importlib.import_module(f"{__package__}.simulation")
    quiet = _Quiet()  # the probe's own notices (a saturation, a fallback) belong to the run, said there
    log = logging.getLogger(LOGGER)
    log.addFilter(quiet)
    try:
        tr = _RUN(probe_scene, keep=True)
    finally:
        log.removeFilter(quiet)
    L = np.zeros((tr.t.size, 3))
    for kind in ("aero", "srp"):
        if f"tau_{kind}_x" in tr.columns:
            L += tr.cols(f"tau_{kind}_x", f"tau_{kind}_y", f"tau_{kind}_z")
    nu = tr.cols("eclipse")[:, 0] if "eclipse" in tr.columns else None
    return torque_rates(tr.t, L, nu)


def choice(scene, params, period: float, n_per_out: int, thrust: bool = False, flight: bool = False,
           law=None) -> dict:
    """``{"ticks": N, "bound_rad": b or None, "why": reason or None}``: the largest of
    :data:`CANDIDATES` (at most ``n_per_out``, the ticks per output row) whose bound is inside
    :data:`TARGET_RAD` for ``scene`` flown with the pd law's ``params`` at ``period`` [s]; 0 with
    the reason when the bound does not apply. Kept per scene content and the law's class ``law``
    (its source file keys the disk copy), one probe each."""
    why = _why_not(scene, params, thrust, flight)
    if why is not None:
        return {"ticks": 0, "bound_rad": None, "why": why}
    try:
        probe_scene = _probe_scene(scene)
    except Exception as e:  # noqa: BLE001 - a scene the probe cannot fly runs every stage
        return {"ticks": 0, "bound_rad": None, "why": f"the probe failed: {type(e).__name__}"}
    key = probe_scene.model_dump_json(exclude={"montecarlo"}) + f"|{period!r}|{n_per_out}|{_file_key(law)}"
    if key in _CHOICES:
        _CHOICES.move_to_end(key)
        return _CHOICES[key]
    path = _disk_path(key)
    if path is not None and path.is_file():  # the same scene probed by an earlier process
        try:
            got = json.loads(path.read_text())
            out = {k: got[k] for k in ("ticks", "bound_rad", "why")}
            ok = out["ticks"] in (0, *CANDIDATES) and out["ticks"] <= n_per_out
        except (OSError, ValueError, KeyError, TypeError):
            ok = False  # unreadable: probe again and write it anew
        if ok:
            _remember(key, out)
            return out
    try:
        M1, M2, fast = _probe(probe_scene)
    except Exception as e:  # noqa: BLE001 - a scene the probe cannot fly runs every stage (its own run says why it fails)
        out = {"ticks": 0, "bound_rad": None, "why": f"the probe failed: {type(e).__name__}"}
        _remember(key, out)
        return out
    if not all(math.isfinite(v) for v in (M1, M2, *(m for f in fast for m in f))):
        return {"ticks": 0, "bound_rad": None, "why": "the probe's torque is not finite"}
    I_min = float(np.linalg.eigvalsh(np.asarray(scene.body.inertia, float)).min())
    wn, zeta = float(params.bandwidth), float(params.damping)
    out = {"ticks": 0, "bound_rad": None, "why": f"no rate's bound is inside {TARGET_RAD:g} rad"}
    for n in CANDIDATES:
        b = hold_bound_rad(n * period, M1, M2, fast, I_min, wn, zeta)
        if n <= n_per_out and b <= TARGET_RAD:
            out = {"ticks": n, "bound_rad": b, "why": None}
            break
    _remember(key, out)
    if path is not None:
        try:
            tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp")
            tmp.write_text(json.dumps({**out, "M1": M1, "M2": M2, "fast": fast}))
            os.replace(tmp, path)
        except OSError:
            pass  # a cache that cannot be written: the next process probes again
    return out


def _remember(key: str, out: dict) -> None:
    _CHOICES[key] = out
    if len(_CHOICES) > KEEP:
        _CHOICES.popitem(last=False)


_CODE: list[str] = []  # the code's fingerprint, once per process


def _file_key(law) -> str:
    """The law class's source file, its size and modification time ("" when unknown)."""
    try:
        f = Path(inspect.getsourcefile(law) or "")
        st = f.stat()
    except (TypeError, OSError):
        return ""
    return f"{f}:{st.st_size}:{st.st_mtime_ns}"


def _code_key() -> str:
    """What the probe's answer depends on besides the scene: stationbed's source files (their
    sizes and modification times: an edit or another version probes anew)."""
    if not _CODE:
        root = Path(__file__).resolve().parents[1]
        h = hashlib.sha256()
        for f in sorted(root.rglob("*.py")):
            st = f.stat()
            h.update(f"{f.relative_to(root)}:{st.st_size}:{st.st_mtime_ns};".encode())
        _CODE.append(h.hexdigest())
    return _CODE[0]


def _disk_path(key: str) -> Path | None:
    """Where the choice for ``key`` is kept across processes: the compile cache's ``rates``
    folder (the compile cache's safety checks apply), None without a usable cache."""
    d = cache_dir()
    if d is None:
        return None
    try:
        (d / "rates").mkdir(mode=0o700, exist_ok=True)
    except OSError:
        return None
    name = hashlib.sha256((_code_key() + "|" + key).encode()).hexdigest()[:32]
    return d / "rates" / f"probe_{name}.json"


def auto_choice(loop) -> dict:
    """:func:`choice` for a closed loop (its law, period, rows, thrusters and sensors)."""
    return choice(loop.scene, getattr(loop.ctrl, "params", None), loop.period, loop.n_per_out,
                  getattr(loop, "thrust", None) is not None, getattr(loop, "flight", None) is not None,
                  type(loop.ctrl))


def scene_choice(scene) -> dict:
    """:func:`choice` for ``scene`` as a closed loop would fly it (a Monte Carlo resolves its
    nominal scene once and flies every sample at that rate); kept per scene object too."""
    hit = _BY_ID.get(id(scene))
    if hit is not None and hit[0] is scene:
        return hit[1]
    out = _scene_choice(scene)
    _BY_ID[id(scene)] = (scene, out)
    if len(_BY_ID) > KEEP:
        _BY_ID.popitem(last=False)
    return out


def _scene_choice(scene) -> dict:
    from .laws import build_controller

    sim, spec = scene.simulation, scene.controller
    if spec is None:
        return {"ticks": 0, "bound_rad": None, "why": "no controller"}
    if spec.name != "pd":
        return choice(scene, None, spec.period, 1, bool(scene.thruster), bool(scene.sensor))  # (says why)
    law = build_controller(spec, base_dir=scene.folder)
    return choice(scene, getattr(law, "params", None), spec.period, int(round(sim.output_dt / spec.period)),
                  bool(scene.thruster), bool(scene.sensor), type(law))


def g_norms(I_kg_m2: float, omega_n: float, zeta: float) -> tuple[float, float, float]:
    """Norms of one axis of the linearised PD loop ``I θ̈ + 2 ζ ω_n I θ̇ + ω_n² I θ = e``:
    ``(‖g‖₁, ‖ġ‖₁ bound, max |g| bound)`` of its torque-to-angle impulse response
    ``g(t) = exp(-ζ ω_n t) sin(ω_d t) / (I ω_d)``, ``ω_d = ω_n √(1 - ζ²)`` (0 < ζ < 1).

    ``‖g‖₁ = coth(π ζ / (2 √(1 - ζ²))) / (I ω_n²)`` (the integral of |e^{-at} sin bt| is
    ``b coth(π a / 2b) / (a² + b²)``); ``|ġ| <= e^{-ζ ω_n t} / (I √(1 - ζ²))`` gives
    ``‖ġ‖₁ <= 1 / (I ζ ω_n √(1 - ζ²))``; ``|g| <= 1 / (I ω_d)``.
    """
    s = math.sqrt(1.0 - zeta * zeta)
    g1 = 1.0 / math.tanh(math.pi * zeta / (2.0 * s)) / (I_kg_m2 * omega_n**2)
    return g1, 1.0 / (I_kg_m2 * zeta * omega_n * s), 1.0 / (I_kg_m2 * omega_n * s)


def hold_bound_rad(delta_s: float, M1: float, M2: float, fast: list[tuple[float, float]], I_kg_m2: float,
                   omega_n: float, zeta: float) -> float:
    """Bound on the attitude change [rad] that holding the environment torque over blocks of
    ``delta_s`` (extrapolated to the block's middle, module docstring) makes in a PD loop.

    Parameters
    ----------
    delta_s : float  Block length N h [s].
    M1, M2 : float  Largest |dL/dt| [N m/s] and |d²L/dt²| [N m/s²] of the environment torque
        (any axis) where it is smooth.
    fast : list of (duration [s], largest |dL/dt| [N m/s])  The stretches where it is not
        (penumbra crossings: the shadow fraction's kinks and its fast change between them).
    I_kg_m2, omega_n, zeta : float  Smallest principal inertia, the loop's ω_n [rad/s] and ζ.

    Notes
    -----
    Over a block ``[t_k, t_k + Δ]`` the error ``e = L - L_hold`` is, by Taylor's theorem, a
    zero-mean ramp ``L̇_k (s - Δ/2)`` plus a remainder ``|r| <= (3/4) M2 Δ²`` (``s²/2`` from L,
    ``Δ²/4`` from the slope of the extrapolation). The angle is ``θ = ∫ g(t - τ) e(τ) dτ``:
    the remainder gives at most ``‖g‖₁ (3/4) M2 Δ²``; the ramp, integrated by parts once
    (its integral ``S`` vanishes at each block's ends and ``|S| <= M1 Δ² / 8``), at most
    ``‖ġ‖₁ M1 Δ² / 8``. In a fast stretch of duration ``T`` and slope ``M1f`` (plus two blocks
    either side, whose extrapolation straddles it) ``|e| <= 2 M1f Δ``, so it adds at most
    ``max|g| 2 M1f Δ (T + 4 Δ)``, each stretch in full (they are summed, as if they were
    simultaneous). Per axis, decoupled, rigid: the linearised loop (docs/design.md).
    """
    g1, gd1, gmax = g_norms(I_kg_m2, omega_n, zeta)
    d = delta_s
    smooth = g1 * 0.75 * M2 * d * d + gd1 * M1 * d * d / 8.0
    return smooth + sum(gmax * 2.0 * m1 * d * (T + 4.0 * d) for T, m1 in fast)


def torque_rates(t, L, nu=None):
    """``(M1, M2, fast)`` of :func:`hold_bound_rad` from a sampled torque ``L`` (N, 3) [N m] at
    times ``t`` (N,) [s]: finite differences where the shadow fraction ``nu`` is 0 or 1 (both
    neighbours too), the penumbra stretches (``0 < nu < 1``) as ``fast`` with their largest
    first difference. Sampling finer than the block length is the caller's part (the
    differences see nothing between samples)."""
    t, L = np.asarray(t, float), np.asarray(L, float)
    dt = np.diff(t)
    d1 = np.diff(L, axis=0) / dt[:, None]
    d2 = np.diff(d1, axis=0) / (0.5 * (dt[1:] + dt[:-1]))[:, None]
    if nu is None:
        return float(np.abs(d1).max()), float(np.abs(d2).max()), []
    pen = (np.asarray(nu) > 1e-12) & (np.asarray(nu) < 1 - 1e-12)
    bad = pen.copy()
    bad[1:] |= pen[:-1]
    bad[:-1] |= pen[1:]
    ok1 = ~(bad[1:] | bad[:-1])
    ok2 = ok1[1:] & ok1[:-1]
    fast = []
    i = 0
    while i < len(pen):
        if pen[i]:
            j = i
            while j + 1 < len(pen) and pen[j + 1]:
                j += 1
            a, b = max(i - 1, 0), min(j + 1, len(t) - 1)
            fast.append((float(t[b] - t[a]), float(np.abs(d1[a:b]).max())))
            i = j + 1
        else:
            i += 1
    return float(np.abs(d1[ok1]).max()), float(np.abs(d2[ok2]).max()), fast
