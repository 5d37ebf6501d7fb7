"""Times where the Earth's shadow changes form along a scene's orbit (issue 14's speed).

The shadow fraction ν (:mod:`stationbed.model.sun`) depends only on the station's position and
the sun, which is fixed over a run; the orbit is analytic (:mod:`stationbed.model.orbit`). So
the instants where ν has a kink or a jump are known before the run:

* conical: the penumbra's outer edge ``c = a + b`` (ν leaves 1) and the umbra's edge
  ``c = b - a`` (ν reaches 0), with ``a``, ``b``, ``c`` the sun's and the Earth's apparent radii
  and their separation (Montenbruck & Gill 3.4.2, as in :func:`~stationbed.model.sun.shadow_conical`);
* cylindrical: where the distance from the Earth-sun line crosses the Earth's radius behind the
  Earth (ν jumps between 0 and 1);
* a night-glider joint switches its drive law where ν crosses 1/2
  (:meth:`~stationbed.model.station.StationModel._glider_acceleration`).

An adaptive integrator that steps across such an instant shrinks its step to resolve it and
then regrows it (~150-450 RHS evaluations per orbit on the ISS scenes, docs/design.md); cut
there, each smooth piece is integrated on its own. A kink (conical ν) is cut at the edge; a jump
(cylindrical ν, a glider's switch) on both sides of it (:data:`JUMP_PAD_S`). The physics is
unchanged. Only adaptive open-loop runs are cut (:func:`stationbed.run.segments.smooth_cuts`): a
fixed-step run keeps its steps, and so its numbers, and a fused closed loop stays fused.

Each edge is a zero of a smooth switching function of time: sampled at :data:`SAMPLES_PER_ORBIT`
points per orbit (the penumbra, ~8 s in LEO, is far wider than the sampling is fine in the
switching function's own terms: each function crosses zero once per eclipse, transversally
unless the orbit only grazes the shadow) and each sign change refined by Brent's method to
:data:`EDGE_XTOL_S`.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import brentq

from ..core.constants import R_EARTH_M
from .environment import sun_direction_N
from .orbit import orbit_numeric, orbit_params, orbit_plane
from .sun import R_SUN_M, shadow_conical, sun_distance_m

__all__ = ["shadow_functions", "shadow_edges", "SAMPLES_PER_ORBIT", "EDGE_XTOL_S", "JUMP_PAD_S"]

#: sampling of the switching functions (per orbit period, and at least every 60 s)
SAMPLES_PER_ORBIT = 720
#: Brent tolerance of an edge time [s]: well inside the first step dop853 takes after a cut
EDGE_XTOL_S = 1e-6
#: a jump is cut on both sides, this far from the edge [s]: ten times the edge's tolerance, so that
#: every stage of the steps before (after) the jump sees the value before (after) it (one cut on
#: the jump would leave it inside the last step, within 1e-6 s of its end, and that step would be
#: rejected down to that size); the step across the 2e-5 s between errs by 2e-5 s x the jump
JUMP_PAD_S = 1e-5


def _angles(r, s_N, dist):
    """Apparent radii of the sun (a) and the Earth (b) and their separation (c) [rad] seen from
    ``r`` (three components, floats or arrays over t), as in :func:`~stationbed.model.sun.shadow_conical`."""
    sqrt, asin, acos, clip = _fns(r[0])
    d = [dist * s_N[k] - r[k] for k in range(3)]
    rn = sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2])
    dn = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
    a, b = asin(R_SUN_M / dn), asin(R_EARTH_M / rn)
    c = acos(clip(-(r[0] * d[0] + r[1] * d[1] + r[2] * d[2]) / (rn * dn)))
    return a, b, c


def _fns(x):
    """sqrt, asin, acos and a clip to [-1, 1]: math's for a float (Brent's steps), numpy's for arrays."""
    if isinstance(x, float):
        return math.sqrt, math.asin, math.acos, lambda v: min(max(v, -1.0), 1.0)
    return np.sqrt, np.arcsin, np.arccos, lambda v: np.clip(v, -1.0, 1.0)


def shadow_functions(scene) -> list:
    """The station's position ``pos(t)`` (three components, floats or arrays over t) and the
    switching functions of the scene's shadow edges, each as ``(g, jump)``: ``g(pos(t))``
    (vectorised over t) is zero at the edge; ``jump`` says whether what the model reads jumps
    there (the cylinder's ν, a glider's drive law) rather than only having a kink. Empty without
    an eclipse model, or when nothing in the scene reads ν."""
    sun = scene.sun
    if sun is None or sun.eclipse == "none" or scene.orbit is None:
        return None, []
    s_N = sun_direction_N(sun, *orbit_plane(scene.orbit))
    dist = sun_distance_m(sun)

    po = orbit_params(scene.orbit)

    def pos(t):  # r_N [m], three components (floats or arrays over t)
        if scene.orbit.kepler:
            r = np.asarray(orbit_numeric(scene.orbit, t).r_N, float)
            return r[0], r[1], r[2]
        radius, _, u0, n, ci, si = (float(v) for v in po)  # the circular orbit's position, as
        arg = u0 + n * t  # orbit.orbit_at has it (without its frames, which cost a matrix per time)
        cu, su = (math.cos(arg), math.sin(arg)) if isinstance(arg, float) else (np.cos(arg), np.sin(arg))
        return radius * cu, radius * (su * ci), radius * (su * si)

    out = []
    srp = any(t.kind == "srp" for t in scene.torque)
    glider = any(getattr(getattr(a, j), "night", "track") == "glider" for a in scene.appendage for j in ("alpha", "beta"))
    if sun.eclipse == "cylindrical":
        def behind(r):  # R_E - (distance from the Earth-sun line) behind the Earth, R_E - |r| ahead
            # (continuous: equal where along = 0; > 0 exactly in the shadow)
            along = s_N[0] * r[0] + s_N[1] * r[1] + s_N[2] * r[2]
            r2 = r[0] * r[0] + r[1] * r[1] + r[2] * r[2]
            perp = np.sqrt(np.maximum(r2 - along * along, 0.0))
            return np.where(along < 0, R_EARTH_M - perp, R_EARTH_M - np.sqrt(r2))
        if srp or glider:
            out.append((behind, True))
        return pos, out
    if srp:
        out.append((lambda r: (lambda a, b, c: c - (a + b))(*_angles(r, s_N, dist)), False))
        out.append((lambda r: (lambda a, b, c: c - (b - a))(*_angles(r, s_N, dist)), False))
    if glider:
        out.append((lambda r: shadow_conical(r, s_N, dist) - 0.5, True))
    return pos, out


def shadow_edges(scene, duration: float) -> list[float]:
    """Sorted times in (0, duration) [s] where the scene's shadow fraction has a kink or a jump,
    or a night glider switches (see the module notes); empty when nothing reads the shadow."""
    pos, funcs = shadow_functions(scene)
    if not funcs:
        return []
    period = 2.0 * math.pi / scene.orbit.mean_motion
    n = max(2, int(math.ceil(duration / min(period / SAMPLES_PER_ORBIT, 60.0))) + 1)
    ts = np.linspace(0.0, duration, n)
    rs = pos(ts)
    edges = set()
    for g, jump in funcs:
        gs = g(rs)
        for k in np.nonzero(np.sign(gs[:-1]) * np.sign(gs[1:]) < 0)[0]:
            e = float(brentq(lambda t: float(g(pos(t))), ts[k], ts[k + 1], xtol=EDGE_XTOL_S))
            edges.update((e - JUMP_PAD_S, e + JUMP_PAD_S) if jump else (e,))
    return sorted(e for e in edges if 0.0 < e < duration)
