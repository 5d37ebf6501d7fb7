"""The shadow's edges found before a run (stationbed/model/shadow_edges.py) and the open-loop cuts there.

Truths used (none calls the finder's switching functions):

* the library's shadow fraction ν (:func:`shadow_conical`, tested against plane geometry in
  tests/test_eclipse.py) sampled every :data:`FINE_S` along the orbit, with positions written in
  the test (circular: ``r (cos u, sin u cos i, sin u sin i)``, ``u = u0 + n t``) or from the
  two-body orbit (tested in tests/test_orbit*.py): the penumbra's outer edge is where ν leaves 1,
  the umbra's where it reaches 0, a glider's switch where it crosses 1/2;
* the cylindrical shadow's entry and exit in closed form for a circular orbit:
  ``cos β cos(u - u_noon) = -sqrt(1 - (R_E/r)²)``;
* a jump (the cylinder, a glider's switch) is cut on both sides, at ±JUMP_PAD_S;
* a run cut at the edges agrees with the same run uncut (the physics is unchanged) to the
  integrator's tolerance, and dop853 spends fewer RHS evaluations.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import stationbed
from stationbed.model import shadow_edges as se
from stationbed.model.environment import sun_direction_N
from stationbed.model.orbit import orbit_numeric, orbit_plane
from stationbed.model.sun import shadow_conical, sun_distance_m
from stationbed.run import segments, simulation

ROOT = Path(__file__).resolve().parents[1]
#: the fine sampling of ν [s]; an edge found by the finder must fall within one sample of ν's change
FINE_S = 0.05
#: the closed-form cylindrical edges against the finder's (its Brent tolerance, 1e-6 s, plus the
#: orbit's u(t) rounding at 5e3 s): [s]
CLOSED_FORM_S = 1e-4
#: a cut run against the uncut one: both at rtol 1e-9 over one orbit; the attitude states differ by
#: the two runs' own errors, a few times rtol relative to the unit quaternion and to the rates
AGREE_REL = 1e-6
R_E = 6378137.0


def _scene(eclipse="conical", torque=("srp",), **orbit):
    gg = stationbed.load_scene(ROOT / "scenarios" / "iss_lvlh_gravity_gradient.toml")
    changes = {"torque": [{"kind": k} for k in torque], "sun": {"beta": 0.1, "u_noon": 0.5, "eclipse": eclipse}}
    if orbit:
        changes["orbit"] = orbit
    return gg.replace(changes)


def _nu_fine(scene, t0, t1):
    """ν sampled every FINE_S on [t0, t1], positions from the orbit (the test's circular formula)."""
    ts = np.arange(t0, t1, FINE_S)
    o = scene.orbit
    if o.kepler:
        r = np.asarray(orbit_numeric(o, ts).r_N)
    else:
        u = o.u0 + o.mean_motion * ts
        r = o.radius_m * np.array([np.cos(u), np.sin(u) * math.cos(o.inclination), np.sin(u) * math.sin(o.inclination)])
    s_N = sun_direction_N(scene.sun, *orbit_plane(o))
    return ts, shadow_conical(r, s_N[:, None], sun_distance_m(scene.sun))


def _changes(ts, nu, level):
    """Times between samples where ν crosses ``level`` or leaves/reaches it (1 or 0)."""
    if level in (0.0, 1.0):
        at = nu == level
        k = np.nonzero(at[:-1] != at[1:])[0]
    else:
        k = np.nonzero((nu[:-1] - level) * (nu[1:] - level) < 0)[0]
    return [(ts[i], ts[i + 1]) for i in k]


@pytest.mark.parametrize("elements", [None, {"a": 6.9e6, "e": 0.02, "i": 0.9, "raan": 0.3, "argp": 1.0, "nu": 0.0}],
                         ids=["circular", "eccentric"])
def test_conical_edges_are_where_the_sampled_shadow_changes(elements):
    scene = _scene()
    if elements is not None:
        scene = scene.replace({"orbit": {"elements": elements, "gravity_gradient": True}})
    T = 2 * math.pi / scene.orbit.mean_motion
    edges = se.shadow_edges(scene, 2 * T)
    ts, nu = _nu_fine(scene, 0.0, 2 * T)
    truth = sorted(_changes(ts, nu, 1.0) + _changes(ts, nu, 0.0))
    assert len(truth) == 8  # two orbits: penumbra in, umbra in, umbra out, penumbra out
    assert len(edges) == len(truth)
    for e, (lo, hi) in zip(edges, truth):
        assert lo <= e <= hi


def test_cylindrical_edges_match_plane_geometry():
    scene = _scene("cylindrical")
    o, sun = scene.orbit, scene.sun
    T = 2 * math.pi / o.mean_motion
    half = math.acos(-math.sqrt(1 - (R_E / o.radius_m) ** 2) / math.cos(sun.beta))  # |u - u_noon| at the edges
    truth = sorted(((sun.u_noon + s * half - o.u0) % (2 * math.pi)) / o.mean_motion + k * T for s in (-1, 1) for k in (0, 1))
    edges = np.array(se.shadow_edges(scene, 2 * T)).reshape(-1, 2)  # a jump: cut on both sides
    assert np.allclose(edges[:, 1] - edges[:, 0], 2 * se.JUMP_PAD_S, rtol=1e-6, atol=0)
    assert np.allclose(edges.mean(axis=1), truth, rtol=0, atol=CLOSED_FORM_S)


def test_glider_switch_is_where_the_shadow_crosses_one_half():
    glider = stationbed.load_scene(ROOT / "scenarios" / "iss_night_glider.toml")
    scene = glider.replace({"torque": [], "surface": [], "sun": {**glider.sun.model_dump(exclude_unset=True), "eclipse": "conical"}})
    T = 2 * math.pi / scene.orbit.mean_motion
    edges = np.array(se.shadow_edges(scene, T)).reshape(-1, 2).mean(axis=1)  # a jump: cut on both sides
    ts, nu = _nu_fine(scene, 0.0, T)
    truth = _changes(ts, nu, 0.5)
    assert len(truth) == 2 and len(edges) == 2
    for e, (lo, hi) in zip(edges, truth):
        assert lo <= e <= hi


@pytest.mark.parametrize("eclipse, torque", [("none", ("srp", "aero")), ("conical", ("aero",)), ("conical", ())],
                         ids=["no_eclipse", "aero_only", "gravity_gradient_only"])
def test_no_cuts_when_nothing_reads_the_shadow(eclipse, torque):
    scene = _scene(eclipse, torque)
    assert se.shadow_edges(scene, 3e4) == []


@pytest.mark.parametrize("eclipse", ["conical", "cylindrical"])
def test_cut_run_agrees_with_uncut_and_costs_fewer_rhs(monkeypatch, eclipse):
    surfaces = [s.model_dump(exclude_unset=True)
                for s in stationbed.load_scene(ROOT / "scenarios" / "iss_lvlh_hold.toml").surface if s.size is not None]
    scene = _scene(eclipse).replace({"surface": surfaces})
    T = 2 * math.pi / scene.orbit.mean_motion
    cut = stationbed.simulate(scene, duration=T)
    monkeypatch.setattr(simulation, "smooth_cuts", lambda *a: [])
    uncut = stationbed.simulate(scene, duration=T)
    assert segments.smooth_cuts(scene, T, stationbed.integrators.DOP853)  # the cuts were there
    assert cut.meta["n_rhs"] < uncut.meta["n_rhs"]
    for col in ("qw", "qx", "qy", "qz"):
        assert np.max(np.abs(np.asarray(cut[col]) - np.asarray(uncut[col]))) < AGREE_REL
    w = np.array([np.asarray(uncut[c]) for c in ("wx", "wy", "wz")])
    scale = np.max(np.abs(w))
    assert np.max(np.abs(np.array([np.asarray(cut[c]) for c in ("wx", "wy", "wz")]) - w)) < AGREE_REL * scale
