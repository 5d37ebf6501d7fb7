"""The state at t = 0: attitude and rate (from LVLH when the scene says so), the formulation's
state with the scene's extra states, and the characteristic scales of the dimensionless atol."""

from __future__ import annotations

import numpy as np

from ..core.compile import FastCall
from ..core.rotation import dcm, quat_from_dcm
from ..model.environment import C_ON, omega_ON_O
from ..model.orbit import orbit_numeric
from ..scene import Scene
from .system import System

__all__ = ["from_lvlh", "initial_state", "initial_x", "characteristic_scales", "RATE_SCALE_FLOOR_RAD_S"]


def from_lvlh(orbit, q_BO, omega_BO_B) -> tuple[np.ndarray, np.ndarray]:
    """``(q_BN, omega_BN_B)`` at t = 0 from an attitude and rate relative to LVLH.

    The LVLH frame and its rate are the orbit's at t = 0 (:mod:`stationbed.model.orbit`); on a
    two-body orbit ``omega_ON_O = (0, -h/r², 0)``.
    """
    C_BO = dcm(np.asarray(q_BO, dtype=float))
    if not orbit.kepler:  # circular: the numbers it has always had
        q = quat_from_dcm(C_BO @ C_ON(orbit.u0, orbit.inclination))
        return q, np.asarray(omega_BO_B, dtype=float) + C_BO @ omega_ON_O(orbit.mean_motion)
    o = orbit_numeric(orbit, 0.0)
    return quat_from_dcm(C_BO @ o.C_ON), np.asarray(omega_BO_B, dtype=float) + C_BO @ o.omega_ON_O


def initial_state(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """``(q_BN, omega_BN_B)`` at t = 0, converting from LVLH when ``initial.frame = 'lvlh'``."""
    q = np.array(scene.initial.q_BN, dtype=float)
    w = np.array(scene.initial.omega_BN_B, dtype=float)
    if scene.initial.frame == "lvlh":
        q, w = from_lvlh(scene.orbit, q, w)
    return q, w


def initial_x(system: System, scene: Scene, q_BN, omega_BN_B, p) -> np.ndarray:
    """The formulation's state at t = 0 with attitude ``q_BN``, rate ``omega_BN_B`` and the
    scene's extra states (CMG, sun-tracking joints)."""
    xe0 = system.formulation.model.initial_extra(scene, q_BN, p)
    init = FastCall.of(system.funcs["init"])
    init.args[0][0] = 0.0
    init.args[1][:] = q_BN
    init.args[2][:] = omega_BN_B
    init.args[3][:] = xe0
    init.args[4][:] = p
    init()
    return init.res[0].copy()


#: Floor of the characteristic rate: 1 mrad/s, the order of a LEO station's orbital rate.
RATE_SCALE_FLOOR_RAD_S = 1e-3


def characteristic_scales(scene: Scene, w0, model, p) -> tuple[float, float]:
    """Rate [rad/s] and momentum [N m s] units for the dimensionless ``atol``.

    rate = max(|ω0|, orbital rate, fastest array rate amplitude, 1 mrad/s); momentum = the
    largest principal moment of the total inertia at t = 0 times that rate.
    """
    rates = [float(np.linalg.norm(w0)), RATE_SCALE_FLOOR_RAD_S]
    if scene.orbit is not None:
        rates.append(scene.orbit.mean_motion)
    for a in scene.appendage:
        for pr in (a.alpha, a.beta):
            if pr.tracked:
                rates.append(pr.max_rate)
            else:
                rates.append(abs(pr.rate) + abs(pr.amp * pr.freq) + sum(abs(st.delta) for st in pr.rate_step))
    rate = max(rates)
    # about O: hub + parallel-axis terms, plus the arrays' own inertia (orientation ignored: a scale)
    I_total = p[model.layout["I0"]].reshape(3, 3) + sum((a.inertia_P for a in scene.appendage), np.zeros((3, 3)))
    I_max = float(np.linalg.eigvalsh(I_total).max())
    return rate, I_max * rate
