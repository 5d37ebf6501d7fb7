"""Star-tracker head (``[[sensor]] kind = "star_tracker"``).

A head measures the attitude of its own frame S (boresight = S's z axis) relative to N:

``q_SN = q_BN ⊗ q_SB``  (``C_SN = C_SB C_BN``, the mounting ``C_SB = dcm(q_SB)``)
``q̃_SN = q_SN ⊗ δq(ν)``, ``δq(ν) = (1, ν/2)/|(1, ν/2)|``, ``C̃_SN = C(δq) C_SN ≈ (E - [ν×]) C_SN``

with the error rotation ν (S components) drawn as ``(nea_cross N₁, nea_cross N₂, nea_about N₃)``:
noise-equivalent angles across the boresight and about it, independent per sample (``2 vec/w``
of ``q_SN⁻¹ ⊗ q̃_SN`` gives ν back exactly).

The measurement is dropped (``valid = 0``) when the boresight is within ``sun_exclusion`` of the
Sun, ``moon_exclusion`` of the Moon, or ``earth_exclusion`` of the Earth's limb (the angle to the
Earth's centre minus its angular radius ``asin(R_E/|R|)``, R_E the WGS-84 equatorial radius).
Angles are ``atan2(|b × s|, b · s)`` (accurate at every angle). A zero Sun or Moon vector (a
run without that body) and a zero position never exclude. A latency of n periods delays
the measurement and its flag by n samples (a delay line in the state); until it has filled,
``valid = 0``.

Faults (issue 34, ``[[fault]]`` kinds ``st_blinded`` and ``st_dropout``: :mod:`.sensor_faults`):
a sample taken inside the window ``blinded`` or ``dropout`` (``[on, off)`` [s], half a period of
margin: :func:`~.sensor_faults.in_window`) is not valid (``valid = 0``; a blinding beyond what
the exclusion angles model, or the head's electronics silent); healthy (the defaults), the
flag's untaken branch: the same numbers.
"""

from __future__ import annotations

import casadi as ca

from ..core.constants import R_EARTH_M
from ..core.rotation import dcm, quat_mult
from ..scene import StarTrackerSensor
from .layout import Layout
from .sensor import Sensor
from .sensor_faults import NEVER_S, in_window

__all__ = ["StarTracker"]

#: an exclusion angle that never excludes [rad] (every angle here is >= -pi/2)
DISABLED_RAD = -4.0


def angle_between(a, b):
    """Angle between two 3-vectors [rad], ``atan2(|a × b|, a · b)`` (casadi)."""
    return ca.atan2(ca.norm_2(ca.cross(a, b)), ca.dot(a, b))


class StarTracker(Sensor):
    """One star-tracker head (see the module docstring)."""

    kind = "star_tracker"
    scene_model = StarTrackerSensor
    PARAMS = Layout(q_SB=4, nea_cross=1, nea_about=1, sun_exclusion=1, earth_exclusion=1, moon_exclusion=1, period=1,
                    blinded=2, dropout=2)
    #: the head's attitude q_SN (scalar first, w >= 0) and the validity flag (1/0)
    OUTPUTS = Layout(q_SN=4, valid=1)
    reads = ("q_BN", "R_N", "sun_N", "moon_N")
    #: ν across (2) and about (1) the boresight
    n_noise = 3

    def _structure(self) -> tuple:
        return (self.entry.n_delay,)

    def _layouts(self):
        # the delay line: one (q_SN, valid) column per period of latency, oldest first (one
        # unused column without latency keeps the state non-empty)
        return Layout(line=(5, max(self.entry.n_delay, 1))), self.PARAMS, self.OUTPUTS

    def _params(self) -> dict:
        e = self.entry

        def angle(v):
            return DISABLED_RAD if v is None else v

        return dict(q_SB=e.mounting(), nea_cross=e.nea_cross, nea_about=e.nea_about,
                    sun_exclusion=angle(e.sun_exclusion), earth_exclusion=angle(e.earth_exclusion),
                    moon_exclusion=angle(e.moon_exclusion), period=float(e.period), blinded=[NEVER_S, NEVER_S],
                    dropout=[NEVER_S, NEVER_S])

    def _initial(self) -> dict:
        line = [[1.0, 0.0, 0.0, 0.0, 0.0]] * max(self.entry.n_delay, 1)  # columns: nothing measured yet
        return dict(line=[list(col) for col in zip(*line)])

    def _step(self, t, x, truth, w, p):
        q_SN = quat_mult(truth["q_BN"], p["q_SB"])
        nu = ca.vertcat(p["nea_cross"] * w[0], p["nea_cross"] * w[1], p["nea_about"] * w[2])
        dq = ca.vertcat(1.0, 0.5 * nu)
        q = quat_mult(q_SN, dq / ca.norm_2(dq))
        q = q / ca.norm_2(q)
        q = ca.if_else(q[0] < 0, -q, q)
        boresight_N = dcm(q_SN)[2, :].T  # S's z axis in N components (true pointing decides)
        R = truth["R_N"]
        r = ca.fmax(ca.norm_2(R), 1.0)  # m (no orbit: R = 0, and the Earth check is off below)
        earth_limb = angle_between(boresight_N, -R / r) - ca.asin(ca.fmin(R_EARTH_M / r, 1.0))
        sun, moon = truth["sun_N"], truth["moon_N"]
        blinded = ca.logic_or(ca.logic_or(
            ca.logic_and(ca.norm_2(sun) > 0.5, angle_between(boresight_N, sun) < p["sun_exclusion"]),
            ca.logic_and(ca.norm_2(moon) > 0.5, angle_between(boresight_N, moon) < p["moon_exclusion"])),
            ca.logic_and(ca.norm_2(R) > 1.0, earth_limb < p["earth_exclusion"]))
        silent = ca.logic_or(in_window(t, p["blinded"], p["period"]), in_window(t, p["dropout"], p["period"]))
        now = ca.vertcat(q, ca.if_else(silent, 0.0, 1.0 - blinded))
        line = x["line"]
        if self.entry.n_delay == 0:
            return dict(line=line), dict(q_SN=now[0:4], valid=now[4])
        oldest = line[:, 0]
        line_next = ca.horzcat(line[:, 1:], now)
        return dict(line=line_next), dict(q_SN=oldest[0:4], valid=oldest[4])
