"""Flight software's fault detection, isolation and mode manager (issue 34 items 2-3): one
symbolic block of the tick (:class:`~.block.Block`, role ``actuator``, the last of the chain).

It sees what flight software sees and nothing of the truth: the measurement fields the law
reads (``h_B``, ``omega_BN_B``, ``gimbal``: the law's view, the estimate's rate with an
``[estimator]``) and the torque request the chain leaves to the CMGs (``tau_B``). Per tick:

1. **CMG momentum residual.** The torque the cluster delivered over the last tick, as the
   momentum it shows says, ``τ_obs = -(h_k - h_k-1)/h - ½(ω_k-1 × h_k-1 + ω_k × h_k)`` (the
   cluster's ``τ = -ḣ - ω × h``, model/cmg/base.py), against what was asked of it then,
   ``r = τ_cmd,k-1 - τ_obs``; ``χ² = |r|²/σ²`` (``[fdir] cmg_sigma_Nm``: the residual's 1σ per
   axis under nominal flight: encoders, the steering's singularity robustness, the tick's
   discretisation). A tick is over the gate when ``χ² > γ``, ``γ`` the chi-squared(3) quantile
   of ``1 - cmg_alpha``; a tick whose request exceeded the cluster's torque (``|τ_cmd,k-1| >
   tau_max``, the plant's ``max_torque``: the limiter cut it, e.g. a thruster pulse's share in
   assist) is not tested (its count held); a fault is declared after ``cmg_persistence`` consecutive ticks over it
   (:func:`persist`). The test is off, its count restarted, while the rate it uses is suspect
   (a gyro detector of the flight's suite says so, :func:`rate_suspect`; ``[fdir]
   cmg_rate_settle_s`` after the filter's switch to the spare gyro): a gyro fault corrupts
   ``ω × h`` (10⁻³ rad/s on ~8000 N m s is 8 N m) and would otherwise be blamed on a CMG.
   With independent ticks, a nominal run's alarms start at a tick with
   probability ``(1 - α) α^N`` (the run of N exceedances preceded by a tick under the gate):
   :func:`false_alarms_per_hour` is that times the ticks per hour.
2. **Isolation.** The unit blamed is the one whose gimbals moved least over the last tick (a
   unit that delivers no torque is one whose gimbals do not answer their rates: its
   tachometers read zero). With ``isolate``, from the next tick it is out of the steering law
   (the memory field ``cmg_excluded``, which the chain's end reads by name: run/blocks.py).
   With ``isolate``, a declaration re-arms the test on the units left: the count waits (at -1)
   for a tested tick under the gate (the isolation worked: a residual that never comes back is
   not blamed on more units), then counts again, and a unit already declared is never blamed
   again (``t_unit``, each unit's declaration time), so a second failure is declared as the
   first was. Without ``isolate`` the first declaration latches (the steering law keeps asking
   the dead unit, the residual stays over the gate). ``t_cmg`` and ``cmg_unit`` keep the first.
3. **Mode manager.** ``hold`` (CMGs alone, thrusters off) < ``assist`` (the thrusters' assist
   logic as ``[thrusters]`` sets it) < ``thruster_only`` < ``drift`` (nothing commanded). The
   base mode starts at ``initial_mode``, rises to ``on_cmg_fault`` at a detection and from
   ``hold`` to ``assist`` when ``|h| >= assist_at`` x capacity (h the working units' momentum as
   flight software knows them, :func:`~.working_momentum.working_momentum`, as the thrusters'
   dump law reads it); a ``[[mode]]`` command overrides it over its window (the last listed wins). The mode is the memory field
   ``fdir_mode`` (the thrusters read it by name); in ``drift`` the CMGs are asked nothing. The
   capacity is the working units' as flight software knows them, the memory field
   ``cmg_capacity`` (the thrusters' dump and hand-over thresholds read it by name too): the
   knowledge's capacity with the units it knows failed (``[cmg] failed``) and those declared
   here left out, from a table by the set declared (``cap_table``, ``2^n_units`` numbers). The
   memory counts the time in each mode (``mode_s``) and the changes (``mode_changes``).

Every number is a parameter (dispersible); the windows are gated by the tick's time with half a
tick of margin (:func:`~.sensor_faults.in_window`).
"""

from __future__ import annotations

import casadi as ca
import numpy as np
from scipy.stats import chi2

from ..core.layout import Layout
from .block import ACT_OUT, Block
from .sensor_faults import NEVER_S, in_window
from .working_momentum import working_momentum

#: one scheduled mode command (a column of the block's ``cmds``): its window [s] and its mode
MODE_CMD = Layout(window=2, mode=1)

__all__ = ["fdir_block", "persist", "gate", "rate_suspect", "false_alarms_per_hour", "residual_cmg", "MODE_NUMBERS", "FdirSpec"]

#: the mode manager's modes by number (the ``fdir_mode`` column; scene/fdir.py MODES)
MODE_NUMBERS = {"hold": 0, "assist": 1, "thruster_only": 2, "drift": 3}
#: ``t_cmg`` before any detection
NOT_YET = -1.0


def gate(alpha: float, dof: int) -> float:
    """The chi-squared gate ``γ`` with ``P(χ²_dof > γ) = alpha``."""
    return float(chi2.isf(alpha, dof))


def false_alarms_per_hour(alpha: float, n: int, ticks_per_hour: float) -> float:
    """Expected alarms per hour of a gate exceeded with probability ``alpha`` per tick
    (independent ticks), declared after ``n`` consecutive exceedances: each tick starts one with
    probability ``(1 - alpha) alpha^n`` (module docstring)."""
    return ticks_per_hour * (1.0 - alpha) * alpha**n


def persist(count, exceed):
    """The consecutive exceedances after this tick: ``count + 1`` over the gate, else 0."""
    return ca.if_else(exceed, count + 1.0, 0.0)


def residual_cmg(tau_prev, h_prev, w_prev, h_B, w_B, h):
    """``r = τ_cmd,k-1 - τ_obs`` (module docstring, item 1) [N m]."""
    tau_obs = -(h_B - h_prev) / h - 0.5 * (ca.cross(w_prev, h_prev) + ca.cross(w_B, h_B))
    return tau_prev - tau_obs


class FdirSpec:
    """The numbers of one scene's ``[fdir]`` and ``[[mode]]`` tables, as the block's parameters."""

    def __init__(self, fdir, modes, n_units: int, gimbals_per_unit: int, capacity_Nms: float,
                 tau_max_Nm: float = NEVER_S, suite=None, capacity_of=None, cmg=None):
        """``capacity_of(declared)``: the working units' capacity flight software knows once the
        units ``declared`` (a tuple of 1-based numbers) are out [N m s]; None: ``capacity_Nms``
        whatever is declared (the block alone, no cluster to ask). ``cmg``: ``(geometry, pc,
        h_held_B)`` of the known gimballed cluster (its numbers, the held momentum of its units
        known failed) for the working units' momentum the ``assist_at`` climb reads; None: the
        measured ``h_B`` itself."""
        self.n_units, self.gpu = int(n_units), int(gimbals_per_unit)
        self.n_cmd = len(modes)
        cmds = [MODE_CMD.pack(window=[m.t, NEVER_S if m.until is None else m.until], mode=MODE_NUMBERS[m.mode])
                for m in modes] or [[NEVER_S] * MODE_CMD.size]
        self.values = dict(sigma=fdir.cmg_sigma_Nm, gamma=gate(fdir.cmg_alpha, 3), persist=fdir.cmg_persistence,
                           isolate=float(fdir.isolate), on_fault=MODE_NUMBERS[fdir.on_cmg_fault],
                           assist_at=fdir.assist_at if np.isfinite(fdir.assist_at) else NEVER_S,
                           tau_max=tau_max_Nm, cmds=np.array(cmds, float).T,
                           cap_table=[capacity_Nms if capacity_of is None or not m else capacity_of(_units(m))
                                      for m in range(2**self.n_units)])
        #: the known cluster's geometry (or None) and its numbers for the working units' momentum
        self.cmg_geo = None if cmg is None else cmg[0]
        self.values["h_held"] = np.zeros(3) if cmg is None else np.asarray(cmg[2], float).reshape(3)
        if cmg is not None:
            self.values["cmg_pc"] = np.asarray(cmg[1], float)
        self.initial_mode = MODE_NUMBERS[fdir.initial_mode]
        self.alpha, self.n = fdir.cmg_alpha, fdir.cmg_persistence
        #: the flight's sensor suite (loop/suite.py) whose gyro detections inhibit the CMG test
        #: (:func:`rate_suspect`), or None (no estimator, no gyro detector: nothing to watch)
        self.suite = suite if suite is not None and suite.mekf is not None and suite.spare_gyro() is not None else None
        self.values["settle"] = fdir.cmg_rate_settle_s


def _units(mask: int) -> tuple:
    """The 1-based units of a declared set's bit mask (bit i: unit i + 1)."""
    return tuple(i + 1 for i in range(mask.bit_length()) if mask >> i & 1)


def known_capacity(table, declared):
    """The entry of ``table`` (one capacity per declared set, by bit mask) for the 0/1 flags
    ``declared`` (casadi): exactly the table's number."""
    code = sum((declared[i] * 2.0**i for i in range(1, declared.numel())), declared[0])
    cap = table[0]
    for m in range(1, table.numel()):
        cap = ca.if_else(code == m, table[m], cap)
    return cap


def rate_suspect(suite, xs, t, settle):
    """Whether the CMG test is inhibited this tick because the rate it uses is suspect, from the
    suite's memory ``xs`` (its detectors' state after the last tick): the redundant gyros over
    their gate or declared with the filter's gyro blamed, or the filter rejecting its heads'
    samples, while the filter still flies its own gyro; or less than ``settle`` s since the
    filter declared its gyro failed and took the spare (the switch's rate step, the spare's bias
    not yet learnt). The gyro flags mirror the suite's switch (loop/suite.py ``_build``)."""
    m, S = suite.mekf, suite.STATE
    xf = S.get(xs, "mekf")
    pair = S.get(xs, "gyro_pair") if suite.pair is not None else None
    spare_blamed = ca.logic_and(pair[1] > 0.5, pair[3] > 1.5) if pair is not None else ca.SX(0)
    switched = ca.logic_and(m.state.get(xf, "gyro_fault") > 0.5, ca.logic_not(spare_blamed))
    suspect = ca.sum1(m.state.get(xf, "reject")) > 0.5
    if pair is not None:
        pair_bad = ca.logic_or(ca.logic_and(pair[1] > 0.5, pair[3] < 1.5),
                               ca.logic_and(pair[0] > 0.5, ca.logic_not(spare_blamed)))
        suspect = ca.logic_or(suspect, pair_bad)
    t_switch = m.state.get(xf, "t_fdir")[len(m.heads)]
    settling = ca.logic_and(switched, t - t_switch < settle)
    return ca.logic_or(ca.logic_and(suspect, ca.logic_not(switched)), settling)


def _layouts(ng: int, n_units: int, n_cmd: int, n_xs: int = 0, n_pc: int = 0):
    X = Layout(tau_prev=3, h_prev=3, w_prev=3, g_prev=ng, have=1, count=1, nis=1, cmg_fault=1, t_cmg=1, cmg_unit=1,
               cmg_excluded=n_units, base_mode=1, fdir_mode=1, mode_s=len(MODE_NUMBERS), mode_changes=1,
               t_unit=n_units, cmg_capacity=1)
    P = Layout(sigma=1, gamma=1, persist=1, isolate=1, on_fault=1, assist_at=1, tau_max=1,
               cmds=(MODE_CMD.size, max(n_cmd, 1)), settle=1, cap_table=2**n_units, h_held=3,
               **({"cmg_pc": n_pc} if n_pc else {}))
    # xs: the suite's memory (the sensing block's, read by name: what it was after the last
    # tick); tau_B last (the composer appends the chain's request to the fields it reads)
    U = Layout(h_B=3, omega_BN_B=3, gimbal=ng, **({"xs": n_xs} if n_xs else {}), tau_B=3)
    out = Layout(fdir_mode=1, nis=1)
    return X, P, U, out


def fdir_block(spec: FdirSpec, name: str = "fdir") -> Block:
    """The block (module docstring) for ``spec``; its memory starts with no previous tick, no
    fault, the initial mode."""
    n_units, gpu = spec.n_units, spec.gpu
    ng = n_units * gpu
    n_xs = spec.suite.STATE.size if spec.suite is not None else 0
    geo = spec.cmg_geo
    X, P, U, out = _layouts(ng, n_units, spec.n_cmd, n_xs, geo.n_par if geo is not None else 0)
    Y = ACT_OUT(0, out)
    k, t, h = ca.SX.sym("k"), ca.SX.sym("t"), ca.SX.sym("h")
    x, u, p = X.symbol("x"), U.symbol("u"), P.symbol("p")
    xs, us, ps = X.split(x), U.split(u), P.split(p)
    tau, h_B, w_B, g = us["tau_B"], us["h_B"], us["omega_BN_B"], us["gimbal"]
    # 1. the residual, its gate and persistence (no previous tick: nothing to compare)
    r = residual_cmg(xs["tau_prev"], xs["h_prev"], xs["w_prev"], h_B, w_B, h)
    nis = xs["have"] * ca.dot(r, r) / ps["sigma"] ** 2
    tested = ca.norm_2(xs["tau_prev"]) <= ps["tau_max"]
    over = nis > ps["gamma"]
    # after a declaration the count waits at -1 for a tick under the gate (the isolation worked), then counts again
    count = ca.if_else(tested, ca.if_else(xs["count"] < 0, ca.if_else(over, -1.0, 0.0), persist(xs["count"], over)),
                       xs["count"])
    if n_xs:  # the rate suspect: the test off and its count restarted (module docstring, item 1)
        count = ca.if_else(rate_suspect(spec.suite, us["xs"], t, ps["settle"]), ca.fmin(count, 0.0), count)
    # armed: before the first declaration; after it, with isolate, while a unit is left undeclared
    declared = [xs["t_unit"][i] >= 0.0 for i in range(n_units)]
    left = sum((ca.logic_not(d) for d in declared[1:]), ca.logic_not(declared[0]))
    armed = ca.logic_or(xs["cmg_fault"] < 0.5, ca.logic_and(ps["isolate"] > 0.5, left > 0.5))
    new = ca.logic_and(count >= ps["persist"], armed)
    count = ca.if_else(new, -1.0, count)  # declared: the count waits for the residual back under the gate
    # 2. isolation: the unit whose gimbals moved least over the last tick (1-based), of those not declared
    moved = [ca.if_else(declared[i], ca.inf,
                        ca.norm_2(g[i * gpu:(i + 1) * gpu] - xs["g_prev"][i * gpu:(i + 1) * gpu])) for i in range(n_units)]
    unit, least = ca.SX(1.0), moved[0]
    for i in range(1, n_units):
        unit = ca.if_else(moved[i] < least, float(i + 1), unit)
        least = ca.fmin(least, moved[i])
    excl = ca.vertcat(*[ca.fmax(xs["cmg_excluded"][i], new * ps["isolate"] * (unit == i + 1)) for i in range(n_units)])
    first = ca.logic_and(new, xs["cmg_fault"] < 0.5)  # t_cmg, cmg_unit: the first declaration's
    t_unit = ca.vertcat(*[ca.if_else(ca.logic_and(new, unit == i + 1), t, xs["t_unit"][i]) for i in range(n_units)])
    # 3. the mode manager (on the capacity flight software knew after the last tick)
    base = ca.fmax(xs["base_mode"], new * ps["on_fault"])
    h_work = working_momentum(geo, ps["cmg_pc"] if geo is not None else None, h_B, ps["h_held"], g, declared)
    climb = ca.logic_and(base < 0.5, ca.norm_2(h_work) >= ps["assist_at"] * xs["cmg_capacity"])
    base = ca.if_else(climb, float(MODE_NUMBERS["assist"]), base)
    mode = base
    for j in range(max(spec.n_cmd, 1)):
        c = ps["cmds"][:, j]
        mode = ca.if_else(in_window(t, MODE_CMD.get(c, "window"), h), MODE_CMD.get(c, "mode"), mode)
    rest = ca.if_else(mode > 2.5, ca.SX.zeros(3), tau)
    x1 = X.pack(tau_prev=rest, h_prev=h_B, w_prev=w_B, g_prev=g, have=1.0, count=count, nis=nis,
                cmg_fault=ca.fmax(xs["cmg_fault"], new), t_cmg=ca.if_else(first, t, xs["t_cmg"]),
                cmg_unit=ca.if_else(first, unit, xs["cmg_unit"]),
                cmg_excluded=excl, base_mode=base, fdir_mode=mode,
                mode_s=ca.vertcat(*[xs["mode_s"][j] + h * (mode == j) for j in range(len(MODE_NUMBERS))]),
                mode_changes=xs["mode_changes"] + (mode != xs["fdir_mode"]), t_unit=t_unit,
                cmg_capacity=known_capacity(ps["cap_table"], ca.vertcat(*[t_unit[i] >= 0.0 for i in range(n_units)])), symbolic=True)
    y = Y.pack(tau_rest_B=rest, on_s=ca.SX(0, 1), torque_B=ca.SX(0, 1), out=ca.vertcat(mode, nis), symbolic=True)
    step = ca.Function(f"{name}_step", [k, t, h, x, u, ca.SX.sym("w", 0), p], [x1, y])
    x0 = X.pack(tau_prev=np.zeros(3), h_prev=np.zeros(3), w_prev=np.zeros(3), g_prev=np.zeros(ng), have=0.0,
                count=0.0, nis=0.0, cmg_fault=0.0, t_cmg=NOT_YET, cmg_unit=0.0, cmg_excluded=np.zeros(n_units),
                base_mode=float(spec.initial_mode), fdir_mode=float(spec.initial_mode), mode_s=np.zeros(len(MODE_NUMBERS)),
                mode_changes=0.0, t_unit=np.full(n_units, NOT_YET), cmg_capacity=spec.values["cap_table"][0])
    return Block(name, "actuator", step, X, P, Layout(), U, Y, key=("fdir", ng, n_units, spec.n_cmd, geo is not None,
                                                                      None if spec.suite is None else spec.suite.STATE.size), x0=x0,
                 p0=P.pack(spec.values))
