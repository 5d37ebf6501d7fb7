"""Steppers behind one interface (DESIGN §7, modelled on scipy's ``OdeSolver``): the registry.

An :class:`Integrator` advances a state across one *smooth segment*: an interval over which the
held input ``u`` is constant and the scene has no discontinuity (the simulation loop splits
the run at torque-window edges and control ticks, so discontinuities are integrated across
exactly, by stopping at them). Within a segment it must land exactly on each requested time.

Registered integrators
----------------------
``dop853``      Dormand-Prince 8(5,3), error-controlled (rtol/atol), dense output; the step
                (12 stages + FSAL + error norm) is generated C and a C driver runs the step
                control, one call per segment (a Python loop when no compiler is present).
                :mod:`.dop853`; the batch lockstep is :mod:`.dop853_batch`.
``rk4``         Classical Runge-Kutta 4, fixed step (``simulation.step``, default 1 s), up to
                64 steps per compiled call; fusable (:mod:`.fixed_step`, table in :mod:`.tableau`,
                stages by :mod:`.rk`).
``lie_rk4``     Runge-Kutta-Munthe-Kaas 4 on the attitude (exp maps of unit quaternions), fixed
                step (:mod:`.lie`).
``lgvi``        Lie-group variational integrator (Lee, Leok & McClamroch), 2nd order, symplectic;
                rigid bodies in the momentum form only (refuses others with the reason) (:mod:`.lie`).
``radau``       Radau IIA order 5, fixed step, simplified Newton in the compiled step (stiff
                cases) (:mod:`.radau`).
``scipy_dop853``, ``scipy_rk45``, ``scipy_radau``, ``scipy_bdf``, ``scipy_lsoda``
                scipy ``solve_ivp`` on the compiled right-hand side: reference paths
                (:mod:`.scipy_ivp`).

Time-dependent terms (array profiles, orbit) are evaluated at the stage times.
"""

from __future__ import annotations

from .base import IntegrationError, Integrator
from .dop853 import DOP853, StepControl
from .fixed_step import RK4, FixedStep
from .lie import LGVI, LieRK4
from .radau import RadauIIA
from .scipy_ivp import ScipyIVP, scipy_variant
from .tableau import CLASSICAL_RK4, TABLEAUS, ButcherTableau

__all__ = [
    "Integrator",
    "IntegrationError",
    "INTEGRATORS",
    "get_integrator",
    "DOP853",
    "StepControl",
    "FixedStep",
    "RK4",
    "LieRK4",
    "LGVI",
    "RadauIIA",
    "ScipyIVP",
    "ButcherTableau",
    "CLASSICAL_RK4",
    "TABLEAUS",
]

#: registry name -> class (``simulation.integrator`` in a scene file)
INTEGRATORS: dict[str, type[Integrator]] = {
    cls.name: cls
    for cls in (
        DOP853,
        RK4,
        LieRK4,
        LGVI,
        RadauIIA,
        ScipyIVP,
        scipy_variant("RK45", 5),
        scipy_variant("Radau", 5),
        scipy_variant("BDF", 1),
        scipy_variant("LSODA", 1),
    )
}


def get_integrator(name_or_cls) -> type[Integrator]:
    """The integrator class for a registry name or an :class:`Integrator` subclass.

    Parameters
    ----------
    name_or_cls : str or type
        A key of :data:`INTEGRATORS`, or any :class:`Integrator` subclass (returned as is).

    Returns
    -------
    type
        The class.

    Raises
    ------
    ValueError
        An unknown name (the message lists the valid ones).
    """
    if isinstance(name_or_cls, type) and issubclass(name_or_cls, Integrator):
        return name_or_cls
    try:
        return INTEGRATORS[name_or_cls]
    except (KeyError, TypeError):
        raise ValueError(f"unknown integrator {name_or_cls!r}; valid: {', '.join(sorted(INTEGRATORS))}") from None
