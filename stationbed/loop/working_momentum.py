"""The CMG cluster's working units' momentum as flight software knows them: one definition,
read by the thrusters' dump and hand-over law (loop/thrusters.py) and the mode manager's
``assist_at`` climb (loop/fdir.py).

``h_B - h_held`` (the measured cluster momentum less the held momentum of the units known failed
from the start, ``[cmg] failed``) until a unit is declared; once one is (``declared``: the
``[fdir]`` block's memory ``t_unit`` >= 0), the sum over the units neither known failed nor
declared of each one's rotor momentum ``h_rotor s_i(δ_i)`` at its measured gimbal angles, from
the known cluster's numbers ``pc`` (``CmgGeometry.params``). A declared unit's momentum is never
the working units' (a stuck gimbal's rotor spins on: all of it is held; a stopped rotor has
none); the working units' own sum is right for both, and flight software knows their rotors.
Until a declaration the first expression exactly (the same numbers).
"""

from __future__ import annotations

import casadi as ca

__all__ = ["working_momentum"]


def working_momentum(geo, pc, h_B, h_held, gimbal, declared):
    """The working units' momentum, B [N m s] (casadi (3, 1)).

    Parameters
    ----------
    geo : GimballedGeometry or None  The known cluster's geometry (None: ``h_B - h_held``).
    pc : casadi SX, shape (geo.n_par, 1)  The known cluster's numbers.
    h_B, h_held : casadi SX, shape (3, 1)  The measured cluster momentum; the held momentum of the
        units known failed from the start [N m s].
    gimbal : casadi SX, shape (geo.n_gimbals, 1)  The measured gimbal angles [rad].
    declared : list of casadi SX  Per unit, 1 once flight software has declared it.
    """
    h = h_B - h_held
    if geo is None:
        return h
    w = [pc[geo.unit_index("working", i + 1)] * (1 - declared[i]) for i in range(geo.n_units)]
    spins = [s for s, _ in geo.spins(gimbal, pc)]
    h_work = pc[0] * sum((w[i] * spins[i] for i in range(1, geo.n_units)), w[0] * spins[0])
    return ca.if_else(sum(declared[1:], declared[0]) > 0, h_work, h)
