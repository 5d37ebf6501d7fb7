"""The compiled system of one (formulation, integrator, structure): right-hand side, outputs,
initial state, jump, measurement, actuation and the integrator's own step, generated as C once
and cached (in this process and on disk)."""

from __future__ import annotations

import time
from dataclasses import dataclass

import casadi as ca

from ..core.compile import EVALUATOR_C, compile_functions, sx_function
from ..formulations import Formulation, get_formulation
from ..integrators import Integrator, get_integrator
from ..loop.cmg_cluster import chain_end
from ..model import StationModel, Structure
from ..model.environment import orbit_position_N, q_ON
from .measurement import measurement_fields

__all__ = ["System", "build_system", "environment_split", "has_environment", "OUT_CHUNK", "chain_end_inputs"]

OUT_CHUNK = 64  # output rows evaluated per compiled call


@dataclass
class System:
    """Compiled functions of one (formulation, integrator, structure)."""

    formulation: Formulation
    integrator_cls: type[Integrator]
    funcs: dict
    build_s: float
    n_out: int
    sx: dict = None  # the SX Functions before compilation (the fused loop composes them)
    #: name -> slice of the compiled output ``out``: omega_BN_B, H_O_N, T, alpha<k>, beta<k>,
    #: h_B, cmg_singularity, track_err<k>, eta, etadot, U_strain (those the scene has)
    out_layout: dict = None
    #: what runs the equations: ``compile.EVALUATOR_C`` (generated C) or ``EVALUATOR_VM``
    #: (casadi's virtual machine: no compiler, or no usable cache; same numbers, slower)
    evaluator: str = EVALUATOR_C
    #: :func:`environment_split`'s SX functions, built on first use
    split: dict = None


_SYSTEMS: dict[tuple, System] = {}


def _split_state(form, x):
    """The attitude ``q_BN`` and the model's extra states (after the form's core) of the state
    ``x``, by the form's state layout (casadi)."""
    xl = form.state_layout
    return xl.get(x, "q_BN"), x[xl.slice(form.rate_field).stop :]


def _track_errors(form, t, x, p):
    """Per array: angle between its normal (+z of P) and the sun [rad] (casadi)."""
    model = form.model
    q_BN, x_extra = _split_state(form, x)
    s_B = model.sun_B(q_BN, p)
    errs = []
    for a in model.arrays(t, q_BN, x_extra, p):
        n_B = a.C_PB[2, :].T  # P's z axis (the array normal), B components
        errs.append(ca.atan2(ca.norm_2(ca.cross(n_B, s_B)), ca.dot(n_B, s_B)))
    return errs


def _tick_functions(form, end, rhs, fs, nx, npar, ng, step) -> list[ca.Function]:
    """One control period fused in one compiled call, for a fusable integrator (RK4).

    ``tick_<cmd>(t, h, x, cmd, u_ext, p) -> (x(t + h), y(t + h), act)``: the actuation at
    ``(t, x)`` (the chain's end, :func:`chain_end_inputs`: the CMG
    cluster's steering law and limits, ``act = [u_cmg, m, rate_limited, saturated]``, or the ideal
    torquer), one step ``step(rhs, t, x, h, u, p)`` (the integrator's ``explicit_step``) of ``h``
    with that input held, and the measurement at the end. Same functions as the generic path
    (the actuator's, the integrator's step, meas), composed, so both paths give the same numbers.
    """
    model = form.model
    by_name = {f.name(): f for f in fs}
    t, h = ca.SX.sym("t"), ca.SX.sym("h")
    x, u_ext, p = ca.SX.sym("x", nx), ca.SX.sym("u_ext", 3), ca.SX.sym("p", npar)
    out = []
    kinds = [("torque", 3)] + ([("rates", ng)] if ng else [])
    for kind, ncmd in kinds:
        cmd = ca.SX.sym("cmd", ncmd)
        act, u, _ = chain_end_inputs(by_name, model, end, "gimbal_rates" if kind == "rates" else "torque", t, h, x, cmd,
                                     u_ext, p)
        x1 = step(rhs, t, x, h, u, p)
        y1 = by_name["meas"](t + h, x1, p)
        out.append(sx_function(f"tick_{kind}", [t, h, x, cmd, u_ext, p], [x1, y1, act]))
    return out


def chain_end_inputs(system_sx: dict, model, end, command: str, t, h, x, cmd, u_ext, p):
    """The actuator chain's end composed into a tick (casadi): ``(act, u, sat)``.

    ``end`` the chain's end (:func:`~stationbed.loop.cmg_cluster.chain_end`): the ideal torquer
    (its one channel on the whole tick, ``FULL_TICK``: ``torque_B`` added to ``u_ext``, no
    split) or the CMG cluster (its function at the plant's state ``x``, the system's
    ``actuate`` / ``actuate_rates`` in ``system_sx``, reading the true body rate and the
    cluster's state ``x_cmg``). ``act`` the end's reported values (``out``; empty for the
    torquer), ``u`` the model's held input by name (``model.input_layout``: ``u_ext``, the
    cluster's ``u_cmg``, the segment's time ``t_step = t + h/2`` with rate steps), ``sat``
    (rate limited, saturated). ``cmd`` the law's command: a torque request, or gimbal rates for
    ``command = "gimbal_rates"``."""
    lay = model.input_layout
    fields = {}
    if model.cmg is None:
        empty = ca.SX(0, 1)
        torque_B = end.function()(t, h, empty, empty, cmd, empty)[3]
        act, sat = ca.SX.zeros(0, 1), ca.SX.zeros(2)
        fields["u_ext"] = u_ext + torque_B
    else:
        if command == "gimbal_rates":
            ng = model.cmg.n_gimbals
            act = system_sx["actuate_rates"](t, x, ca.vertcat(cmd, ca.SX.zeros(max(ng, 1) - ng)), p)
        else:
            act = system_sx["actuate"](t, x, cmd, p)
        o = end.outputs
        fields["u_ext"] = u_ext
        fields["u_cmg"] = o.get(act, "u_cmg")
        sat = ca.vertcat(o.get(act, "rate_limited"), o.get(act, "saturated"))
    if "t_step" in lay:
        fields["t_step"] = t + h / 2  # the segment's time for the side of a rate step
    return act, lay.pack(fields), sat


def build_system(structure: Structure, formulation, integrator) -> System:
    """Build (or fetch from the in-process cache) the compiled functions for a structure."""
    form_cls = get_formulation(formulation)
    integ_cls = get_integrator(integrator)
    key = (form_cls, integ_cls, structure)
    if key in _SYSTEMS:
        return _SYSTEMS[key]
    t0 = time.perf_counter()
    model = StationModel(structure)
    form = form_cls(model)
    nx, npar, nu = form.nx, model.layout.size, model.nu
    t = ca.SX.sym("t")
    t2 = ca.SX.sym("t2")
    x = ca.SX.sym("x", nx)
    u = ca.SX.sym("u", nu)
    p = ca.SX.sym("p", npar)
    q = ca.SX.sym("q", 4)
    w = ca.SX.sym("w", 3)
    xe = ca.SX.sym("xe", model.n_extra + 2 * model.n_modes)
    xdot = form.rhs(t, x, u, p)
    rhs = sx_function("rhs", [t, x, u, p], [xdot])
    if rhs.n_instructions() > integ_cls.RHS_INLINE_MAX_OPS:  # the steps call one compiled RHS (rule 6 of Integrator)
        rhs = sx_function("rhs", [t, x, u, p], [xdot], called=True)
    arrays = form.arrays(t, x, p)
    # the compiled outputs by name (rows.py places them in the CSV columns by these names)
    outs = [("omega_BN_B", form.omega(t, x, p)), ("H_O_N", form.H_O_N(t, x, p)), ("T", form.kinetic_energy(t, x, p))]
    for k, a in enumerate(arrays):
        outs += [(f"alpha{k}", a.angles[0]), (f"beta{k}", a.angles[1])]
    cmg = model.cmg
    q_BN, x_extra = _split_state(form, x)
    if cmg is not None:
        outs.append(("h_B", model.h(x_extra, p)))
        if cmg.gimballed:
            pc = p[model.layout["cmg"]]
            outs.append(("cmg_singularity", cmg.singularity(form.state_layout.get(x, "x_cmg"), pc)))
    if structure.sun:
        outs += [(f"track_err{k}", e) for k, e in enumerate(_track_errors(form, t, x, p))]
    outs += model.environment_outputs(t, q_BN, x_extra, p)  # aero/SRP torques, shadow fraction
    if model.n_modes:
        outs += [("eta", model.eta(x_extra)), ("etadot", form.modal_rates(t, x, p)), ("U_strain", form.strain_energy(t, x, p))]
    out_layout, n = {}, 0
    for name, e in outs:
        out_layout[name] = slice(n, n + e.numel())
        n += e.numel()
    out = sx_function("out", [t, x, p], [ca.vertcat(*(e for _, e in outs))])
    init = sx_function("init", [t, q, w, xe, p], [form.state(t, q, w, xe, p)])
    fs = [rhs, out, out.map("out_map", "serial", OUT_CHUNK, [2], []), init]
    if form.omega_is_state:
        fs.append(sx_function("jump", [t, t2, x, p], [form.jump(t, t2, x, p)]))
    p2 = ca.SX.sym("p2", npar)  # a scheduled step's parameters after it (run/schedule.py)
    fs.append(sx_function("step_jump", [t, x, p, p2], [form.step_jump(t, t, x, p, p2)]))
    # controller side: the measurement vector, and the actuation (steering law + limits)
    ng = 0 if cmg is None else cmg.n_gimbals
    lay = measurement_fields(ng, structure.n_app)
    wv = form.omega(t, x, p)
    gimbals = form.state_layout.get(x, "x_cmg")[0:ng] if ng else ca.SX(0, 1)  # the gimbal angles, by name
    meas = dict(q_BN=q_BN, omega_BN_B=wv, h_B=model.h(x_extra, p), gimbal=gimbals,
                alpha=ca.vertcat(*(a.angles[0] for a in arrays)), beta=ca.vertcat(*(a.angles[1] for a in arrays)))
    if structure.orbit and not structure.orbit_kind:  # circular: the expressions it has always had
        radius, incl, u0, n = (p[model.layout["orbit"]][i] for i in range(4))
        meas.update(r_N=orbit_position_N(u0 + n * t, radius, incl), C_ON=ca.reshape(model.C_ON(t, p).T, 9, 1),
                    q_ON=q_ON(u0 + n * t, incl), omega_ON_O=model.orbit_at(t, p).omega_ON_O)
    elif structure.orbit:
        o = model.orbit_at(t, p)
        meas.update(r_N=o.r_N, C_ON=ca.reshape(o.C_ON.T, 9, 1), q_ON=o.q_ON, omega_ON_O=o.omega_ON_O)
    else:
        meas.update(r_N=ca.DM.zeros(3), C_ON=ca.reshape(ca.DM.eye(3), 9, 1), q_ON=ca.DM([1.0, 0.0, 0.0, 0.0]),
                    omega_ON_O=ca.DM.zeros(3))
    meas["sun_N"] = p[model.layout["sun"]] if structure.sun else ca.DM.zeros(3)
    y = lay.pack(meas, symbolic=True)  # by name, in the layout's order (C_ON row by row)
    fs.append(sx_function("meas", [t, x, p], [y]))
    end = chain_end(model)  # the actuator chain's end: the CMG cluster or the ideal torquer
    if cmg is not None:  # the cluster's plug-in at the plant's state: its per-tick compiled form
        cmd = ca.SX.sym("cmd", 3)
        rates = ca.SX.sym("rates", max(ng, 1))
        r = end.reads.pack(omega_BN_B=wv, x_cmg=form.state_layout.get(x, "x_cmg"))
        pc = p[model.layout["cmg"]]
        fs.append(sx_function("actuate", [t, x, cmd, p], [end.function()(t, 0.0, ca.SX(0, 1), r, cmd, pc)[4]]))
        if ng:
            fs.append(sx_function("actuate_rates", [t, x, rates, p], [end.rates_function()(t, r, rates, pc)]))
    fs.append(sx_function("inertia", [t, x, p], [model.inertia(t, p, arrays)]))
    if integ_cls.fusable:
        fs += _tick_functions(form, end, rhs, fs, nx, npar, ng, integ_cls.explicit_step)
    fs += integ_cls.build(rhs, nx, nu, npar)
    tag = f"{form_cls.name}_{integ_cls.name}_{structure.key}"
    funcs = compile_functions(fs, tag, extra_c=integ_cls.extra_c)
    system = System(
        form, integ_cls, funcs, time.perf_counter() - t0, out.numel_out(0), {f.name(): f for f in fs}, out_layout,
        funcs["__evaluator__"],
    )
    _SYSTEMS[key] = system
    return system


def environment_split(system: System) -> dict | None:
    """The right-hand side without the environment torques, and those torques on their own, for
    a loop that evaluates them at their own rate (``[simulation] environment_rate``,
    docs/design.md "Effects at their own rate"); None when the scene has none.

    Returns ``{"rhs_fast": f(t, x, u, p) -> ẋ, "env_B": g(t, x, p) -> L_env_B}`` (SX Functions,
    not compiled: the fused loop composes them). The environment torques are the kinds with
    ``needs_env`` (aero and SRP on the scene's surfaces, with the shadow fraction inside SRP);
    ``rhs_fast(t, x, u + [L_env_B; 0], p)`` is ``rhs(t, x, u, p)`` up to the order of the sum
    (round-off) when ``L_env_B = env_B(t, x, p)``.
    """
    if system.split is not None:
        return system.split or None
    form = system.formulation
    model = form.model
    if not has_environment(system):
        system.split = {}
        return None
    env_kinds = [k for k in model.torques if k.needs_env]
    fast_model = StationModel(model.structure)
    fast_model.torques = tuple(k for k in fast_model.torques if not k.needs_env)
    fast_model.needs_arrays = False
    fast = type(form)(fast_model)
    nx, nu, npar = form.nx, model.nu, model.layout.size
    t = ca.SX.sym("t")
    x, u, p = ca.SX.sym("x", nx), ca.SX.sym("u", nu), ca.SX.sym("p", npar)
    rhs_fast = sx_function("rhs_fast", [t, x, u, p], [fast.rhs(t, x, u, p)])
    if system.sx["rhs"].n_instructions() > system.integrator_cls.RHS_INLINE_MAX_OPS:
        rhs_fast = sx_function("rhs_fast", [t, x, u, p], [fast.rhs(t, x, u, p)], called=True)
    orbit = model.orbit_at(t, p) if model.structure.orbit else None
    q_BN, _ = _split_state(form, x)
    env = model.environment(q_BN, orbit, p, form.arrays(t, x, p))
    L_B = ca.SX.zeros(3)
    for kind in env_kinds:
        p_k = p[model.layout[kind.kind]] if kind.n_par else None
        L_B = L_B + kind.torque_B(t, q_BN, None, p_k, orbit, env)
    system.split = {"rhs_fast": rhs_fast, "env_B": sx_function("env_B", [t, x, p], [L_B])}
    return system.split


def has_environment(system: System) -> bool:
    """Whether :func:`environment_split` has torques to split off (the kinds with ``needs_env``:
    aero, SRP) in ``system``'s SX functions, without building the split."""
    return system.sx is not None and any(k.needs_env for k in system.formulation.model.torques)
