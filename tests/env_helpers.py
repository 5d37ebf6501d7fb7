"""Shared set-up of the environment-torque tests: a scene's aero/SRP torques and shadow fraction
evaluated by the library's compiled expressions at a given time, attitude and state."""

from __future__ import annotations

import casadi as ca
import numpy as np
from scipy.spatial.transform import Rotation

from stationbed.model import StationModel, Structure
from stationbed.scene import scene_from_dict

#: Earth's rotation rate [rad/s] (IERS 2010), μ [m³/s²], equatorial radius [m] (WGS-84)
OMEGA_E = 7.292115e-5
MU = 3.986004418e14
R_E = 6378137.0


def base_scene(**more) -> dict:
    """A 1e5 kg body at the origin (no arrays), on a circular orbit, no torques yet."""
    d = {
        "name": "env_test",
        "simulation": {"duration": 10.0},
        "body": {"mass": 1.0e5, "inertia": [[1e7, 0, 0], [0, 2e7, 0], [0, 0, 2.5e7]], "cm": [0.0, 0.0, 0.0]},
        "orbit": {"altitude": 420e3, "inclination": 0.9, "u0": 0.7},
    }
    d.update(more)
    return d


def outputs(scene_dict):
    """``f(t, q_BN, xe) -> dict`` of the model's environment outputs (numpy), and the model."""
    scene = scene_from_dict(scene_dict)
    m = StationModel(Structure.of(scene))
    t, q = ca.SX.sym("t"), ca.SX.sym("q", 4)
    xe = ca.SX.sym("xe", m.n_extra + 2 * m.n_modes)
    p = ca.SX.sym("p", m.layout.size)
    outs = m.environment_outputs(t, q, xe, p)
    f = ca.Function("env", [t, q, xe, p], [e for _, e in outs])
    pv = m.params(scene)
    names = [n for n, _ in outs]

    def call(t_, q_, xe_=None):
        xe_ = np.zeros(m.n_extra + 2 * m.n_modes) if xe_ is None else xe_
        res = f(t_, q_, xe_, pv)
        res = res if isinstance(res, (list, tuple)) else [res]
        return {n: np.array(r).ravel() for n, r in zip(names, res)}

    return call, m, scene


def circular_state(scene, t):
    """r_N, v_N of the scene's circular orbit at t, written from DESIGN §5 (not the library)."""
    o = scene.orbit
    R = R_E + o.altitude
    n = np.sqrt(MU / R**3)
    u = o.u0 + n * t
    ci, si = np.cos(o.inclination), np.sin(o.inclination)
    r = R * np.array([np.cos(u), np.sin(u) * ci, np.sin(u) * si])
    v = R * n * np.array([-np.sin(u), np.cos(u) * ci, np.cos(u) * si])
    return r, v, u


def v_rel_N(r, v):
    """Velocity relative to the co-rotating air: v - ω_E ẑ × r."""
    return v - np.cross([0.0, 0.0, OMEGA_E], r)


def vallado_density(h_m):
    """Vallado (2013) Table 8-4 base densities, typed here for 350-500 km, with the scale height
    of each band the log-slope to the next base (the table's H to its rounding, and continuous)."""
    bases = [(350e3, 9.518e-12), (400e3, 3.725e-12), (450e3, 1.585e-12), (500e3, 6.967e-13)]
    k = max(i for i, b in enumerate(bases[:-1]) if b[0] <= h_m)
    (h0, rho0), (h1, rho1) = bases[k], bases[k + 1]
    H = (h1 - h0) / np.log(rho0 / rho1)
    return rho0 * np.exp(-(h_m - h0) / H)


def quat_of_dcm(C_BN):
    """q_BN (scalar first) of a DCM C_BN, with scipy (independent of the library)."""
    x, y, z, w = Rotation.from_matrix(C_BN.T).as_quat()
    return np.array([w, x, y, z])
