"""One run's set-up: the compiled system of a scene, its parameter vector, the state at t = 0
and the integrator with the scene's tolerances scaled to its states.

:func:`~stationbed.run.simulation.simulate` starts every run from :func:`prepare`; so do the
studies that drive an integrator or a compiled function of the system directly
(:mod:`stationbed.studies.probes`), which therefore start from the same numbers as a run.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..integrators import Integrator, get_integrator
from ..model import Structure
from ..scene import Scene
from .initial import characteristic_scales, initial_state, initial_x
from .system import System, build_system

__all__ = ["Prepared", "prepare"]


@dataclass(frozen=True)
class Prepared:
    """Everything a run needs before its first step.

    Attributes
    ----------
    system : System
        The compiled functions of (formulation, integrator, the scene's structure).
    p : ndarray, shape (npar,)
        The scene's parameter vector, laid out by ``system.formulation.model.layout``.
    q_BN : ndarray, shape (4,)
        Attitude of B relative to N at t = 0 (scalar first) [-].
    omega_BN_B : ndarray, shape (3,)
        Angular velocity of B relative to N at t = 0, B components [rad/s].
    x0 : ndarray, shape (nx,)
        The formulation's state at t = 0 (with the scene's extra states).
    rtol : float
        Relative tolerance [-].
    atol : ndarray, shape (nx,)
        Absolute tolerance per state component, in the state's units (the scene's
        dimensionless ``atol`` times the characteristic rate or momentum).
    integrator : Integrator
        A fresh integrator on the system with these tolerances, the step and the scene's
        ``max_step``; its counters start at zero.
    """

    system: System
    p: np.ndarray
    q_BN: np.ndarray
    omega_BN_B: np.ndarray
    x0: np.ndarray
    rtol: float
    atol: np.ndarray
    integrator: Integrator


def prepare(
    scene: Scene,
    formulation=None,
    integrator=None,
    *,
    rtol: float | None = None,
    atol: float | None = None,
    step: float | None = None,
) -> Prepared:
    """Build (or fetch) the compiled system of a scene and set up its run.

    Parameters
    ----------
    scene : Scene
    formulation, integrator : str or class, optional
        Default: the scene's ``simulation.formulation`` / ``simulation.integrator``.
    rtol : float, optional
        Relative tolerance [-]; default the scene's.
    atol : float, optional
        Dimensionless absolute tolerance, in units of the scene's characteristic rate and
        momentum (:func:`~stationbed.run.initial.characteristic_scales`); default the scene's.
    step : float, optional
        Fixed step [s] of fixed-step integrators; default the scene's. Refused (ValueError) with
        an adaptive integrator, as is a scene whose own integrator is adaptive and which sets
        ``simulation.step``: a step is never silently ignored.

    Returns
    -------
    Prepared
    """
    sim = scene.simulation
    formulation = formulation or sim.formulation
    own = integrator is None or integrator == sim.integrator
    integrator = integrator or sim.integrator
    rtol = sim.rtol if rtol is None else rtol
    atol = sim.atol if atol is None else atol
    # a step is never ignored: it is refused where it cannot apply (the scene's step is the fixed
    # step of fixed-step integrators; a caller who overrides with an adaptive one leaves it behind)
    integ_cls = get_integrator(integrator)
    if integ_cls.adaptive and step is not None:
        raise ValueError(
            f"step = {step:g} s applies to fixed-step integrators; '{integ_cls.name}' is adaptive "
            f"(its accuracy is set by rtol and atol; simulation.max_step caps its step)"
        )
    if own and integ_cls.adaptive and sim.step is not None:  # the scene contradicts itself
        raise ValueError(
            f"simulation.step = {sim.step:g} s applies to fixed-step integrators; the scene's integrator "
            f"'{integ_cls.name}' is adaptive (remove step, or choose a fixed-step integrator)"
        )
    if step is None and not integ_cls.adaptive:
        step = sim.step  # the scene's fixed step, for any fixed-step integrator
    system = build_system(Structure.of(scene), formulation, integrator)
    form = system.formulation
    model = form.model
    p = model.params(scene)
    q0, w0 = initial_state(scene)
    rate_scale, momentum_scale = characteristic_scales(scene, w0, model, p)
    atol_vec = form.atol_vector(atol, rate_scale, momentum_scale)
    integ = system.integrator_cls(system.funcs, p, form.nx, rtol=rtol, atol=atol_vec, step=step, max_step=sim.max_step)
    x0 = initial_x(system, scene, q0, w0, p)
    return Prepared(system, p, q0, w0, x0, rtol, atol_vec, integ)
