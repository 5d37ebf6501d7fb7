"""Thrusters (issue 21): the first :class:`~.actuator.Actuator` plug-in. CMG thruster assist,
hand-over to thruster-only control, force mapping, Schmitt pulse modulation, propellant ledger.

Per tick (one casadi expression, :meth:`ThrusterCluster._command`):

1. **Mode and dump law.** ``f = |h| / capacity``, h and the capacity of the working units as
   flight software knows them (:meth:`ThrusterCluster._working_h`: a failed unit it knows of
   from the start, its held momentum left out; with ``[fdir]``, once a unit is declared, the
   units neither known failed nor declared, each one's rotor momentum at its measured gimbal
   angles). Thruster-only control starts at ``f >= handover`` and ends at
   ``f <= handback`` (``mode = "assist"``; ``"thruster_only"``: always; ``"off"``: never
   fires). Dumping starts at ``f >= assist_on`` and stops at ``f <= dump_stop``; the dump
   request is ``ΔH = -(|h| - h_min)/|h| h`` and its torque ``ΔH / dump_time_s``, at most
   ``max_dump_torque_Nm``. Inside an inhibit window nothing fires.
2. **Request.** The thrusters are asked for ``mode · τ_law + dumping · L_dump``.
3. **Mapping** (:func:`mapping_matrices`): minimum norm plus the least shift along positive
   null-space vectors (one per opposed pair of thrusters, or one for the set); where the
   geometry allows, ``M`` and ``v`` are those of the torque *and* force equations, so the
   forces are a pure couple (Σ F_i ĝ_i = 0). Scaled down as a whole when a force exceeds its
   thruster's. (The LP with bounds, :func:`map_lp`, is the per-tick alternative.)
4. **Pulse modulation.** A thruster's requested on-time is ``F_i / F_max,i · h`` plus its
   remainder; below ``min_on_s`` a Schmitt trigger decides (level = requested / min_on_s:
   fire ``min_on_s`` at ``level >= level_on``, none at ``level <= level_off``, in between
   as the previous tick did); above, the request, at most ``h``.
5. **What is left to the CMGs.** ``τ_law - L_thr`` (``L_thr`` the tick's average thruster
   torque) in assist: the CMGs keep holding attitude while the thrusters unload them;
   ``-dumping · L_dump`` in thruster-only control (the law's torque goes to the thrusters).
6. **Ledger.** Per thruster the total on-time; the firings (a pulse that does not continue the
   previous tick's full-length one), the time in thruster-only control, the impulse Σ F t_on
   and the propellant Σ F t_on / (Isp g0), all exact with the on-times.

The torque of thruster i is ``(r_i - c) × F_i ĝ_i`` about the composite mass centre c. The
arrays are balanced about their rotation axes (DESIGN §4), so c does not move as they turn: it
is ``Σ m r / Σ m`` of the body, the arrays and the vehicles docked
(:func:`~stationbed.scene.docking.mass_centre_B`; flexible modes shift it by their modal
displacement, neglected here: ~ m_p |η| / m_total, below a millimetre for the shipped modes),
constant between configuration changes. The executors use the truth's c (the numbers
``torque_B``); the mapping uses the c flight software knows (``M``, ``V`` and ``c_known``, the
knowledge scene's). A docking or undocking (``[[event]]``) moves c: its step sets ``torque_B``
about the new c at the event's tick, and the mapping's numbers when flight software is told
(``update_after_s``; :meth:`ThrusterCluster.configuration_numbers`, run/docking.py), the
compiled code unchanged. Until then the thrusters make ``(c_known - c) × Σ F_i ĝ_i`` more than
asked, ``Σ F_i ĝ_i`` the net force of the pulses (none for an exact pure couple, whose torque
is the same about any point). The force is recorded
(the impulse) but does not change the orbit (docs/loop.md: the orbit is prescribed, and the
ISS's attitude thrusters' net impulse is a pure couple where they can make one).

A visiting vehicle's thrusters (``[[vehicle.thruster]]``,
:func:`~stationbed.scene.thrusters.flown_thrusters`) are channels of this block from t = 0, one
per thruster at each port the vehicle uses in the run, each with an availability number
``avail`` (1 while the vehicle is docked there) that multiplies its valve's on-time; the event's
step sets it. Flight software's mapping gives the thrusters it knows cannot fire zero rows, and
the shifts' supports become numbers (:func:`_masked_shift`), so one compiled block serves every
configuration; scenes without a vehicle's thrusters compile neither (their code as before).
"""

from __future__ import annotations

import hashlib
import math

import casadi as ca
import numpy as np

from ..model.cmg import cmg_geometry, held_momentum_B
from ..scene.docking import configuration_ports, docked_at, mass_centre_B
from ..scene.thrusters import available, flown_thrusters, no_torque_about, no_torque_parts, thruster_owners, torque_arms
from .actuator import Actuator, register_actuator
from .layout import Layout
from .working_momentum import working_momentum

__all__ = ["ThrusterCluster", "G0_M_S2", "mapping_matrices", "map_min_norm_shift", "map_lp", "MODES", "opposed_pairs",
           "supports", "torque_arms"]

#: standard gravity [m/s²] for m_dot = F / (Isp g0) (CGPM 1901, exact)
G0_M_S2 = 9.80665
#: ``[thrusters] mode`` -> its number in the parameters
MODES = {"assist": 0.0, "thruster_only": 1.0, "off": 2.0}
#: a positive null-space vector exists when the LP finds one with all entries >= 1 and the
#: residual of A v is below this fraction of |A| |v| (round-off of HiGHS's solution)
NULL_RESIDUAL_REL = 1e-9
#: the masked shift's candidate for an entry it skips (V_ik = 0): below any -F_i / V_ik a force of
#: at most ~1e6 N over an entry of at least ~1e-290 makes, and finite (x 0 is 0, not NaN)
NO_SHIFT = -1e300


def _positive_null(A: np.ndarray) -> np.ndarray | None:
    """A vector v >= 1 with A v = 0 (scipy HiGHS LP, minimum Σ v), or None when none exists."""
    from scipy.optimize import linprog

    n = A.shape[1]
    res = linprog(np.ones(n), A_eq=A, b_eq=np.zeros(A.shape[0]), bounds=[(1.0, None)] * n, method="highs")
    if res.status != 0:
        return None
    v = res.x
    if np.linalg.norm(A @ v) > NULL_RESIDUAL_REL * np.linalg.norm(A) * np.linalg.norm(v):
        return None
    return v / v.max()


def opposed_pairs(positions, directions, tol: float = 1e-9) -> list[tuple[int, int]] | None:
    """Every thruster matched with one at the same place firing the opposite way (i < j), or
    None when the set does not split into such pairs."""
    P, G = np.asarray(positions, dtype=float), np.asarray(directions, dtype=float)
    free, pairs = list(range(len(P))), []
    while free:
        i = free.pop(0)
        j = next((j for j in free if np.linalg.norm(P[i] - P[j]) <= tol * max(1.0, np.linalg.norm(P[i]))
                  and np.linalg.norm(G[i] + G[j]) <= tol), None)
        if j is None:
            return None
        free.remove(j)
        pairs.append((i, j))
    return pairs


def mapping_matrices(D: np.ndarray, G: np.ndarray, pairs=None) -> tuple[np.ndarray, np.ndarray, bool]:
    """``(M (n, 3), V (n, m), pure)`` of the minimum-norm-plus-shift mapping
    ``F = M L + Σ_k s_k V[:, k]`` (:func:`map_min_norm_shift`).

    ``pure``: M solves the torque and the force equations (``[D; G] F = [L; 0]``, a pure
    couple); otherwise the torque equations alone (the net force is then whatever it is). The
    columns of V are positive null-space vectors of the same rows with disjoint supports: one per
    opposed pair (``pairs``, :func:`opposed_pairs`: ``e_i + e_j``, a pair fired together does
    nothing), else one found by HiGHS (``v >= 1``, ``A v = 0``). V is one zero column when no
    positive null vector exists: forces that come out negative are then clipped to 0 and the
    torque is not exact (use ``mapping = "lp"``, or add thrusters)."""
    n = D.shape[1]
    rk = np.linalg.matrix_rank
    for A, pure in ((np.vstack([D, G]), True), (D, False)):
        # every torque with no net force: D full rank, and the force rows independent of it
        # (a set that makes no force along some axis, e.g. no thruster along x, still qualifies)
        if rk(D) < 3 or (pure and rk(A) < 3 + rk(G)):
            continue
        if pairs:
            V = np.zeros((n, len(pairs)))
            for k, (i, j) in enumerate(pairs):
                V[i, k] = V[j, k] = 1.0
            return np.linalg.pinv(A)[:, :3], V, pure
        v = _positive_null(A)
        if v is not None:
            return np.linalg.pinv(A)[:, :3], v[:, None], pure
    return np.linalg.pinv(D)[:, :3], np.zeros((n, 1)), False


def supports(V) -> list[list[int]]:
    """The thrusters each shift vector (column of V) moves."""
    V = np.asarray(V, dtype=float)
    return [[int(i) for i in np.flatnonzero(V[:, k] > 0)] for k in range(V.shape[1])]


def map_min_norm_shift(M, V, f_max, L, support=None):
    """Forces >= 0 for the torque request ``L`` (casadi or numpy): ``F = M L``, then along each
    shift vector k (a column of ``V``, disjoint supports ``support``, from ``V`` when it is
    numeric) the least shift ``s_k = max_i (-F_i / V_ik)`` that leaves every force it moves
    non-negative (one of them exactly 0: no propellant spent against itself); then all scaled by
    ``1 / max(1, max_i F_i / F_max,i)`` so none exceeds its thruster's (the torque's direction
    kept). Without a shift vector negative forces are clipped to 0."""
    if isinstance(L, (ca.SX, ca.MX)):
        F = ca.mtimes(M, L)
        if support is None:  # the shifts' supports are numbers (a vehicle's thrusters come and go)
            return _masked_shift(F, V, f_max)
        for k, sup in enumerate(support):
            if sup:
                s = -F[sup[0]] / V[sup[0], k]
                for i in sup[1:]:
                    s = ca.fmax(s, -F[i] / V[i, k])
                F = F + s * V[:, k]
        F = ca.fmax(F, 0.0)
        kk = 1.0
        for i in range(F.shape[0]):
            kk = ca.fmax(kk, F[i] / f_max[i])
        return F / kk
    M, V, f_max, L = (np.asarray(a, dtype=float) for a in (M, V, f_max, L))
    V = V.reshape(len(f_max), -1)
    F = M @ L
    for k, sup in enumerate(supports(V) if support is None else support):
        if sup:
            F = F + max(-F[i] / V[i, k] for i in sup) * V[:, k]
    F = np.maximum(F, 0.0)
    return F / max(1.0, float(np.max(F / f_max)))


def _masked_shift(F, V, f_max):
    """:func:`map_min_norm_shift`'s shift and scaling with the supports read from the numbers
    ``V`` (symbolic, (n, m)): along column k the least ``s_k = max_{i: V_ik > 0} (-F_i / V_ik)``,
    none when the column is all zero (a padding column; an entry of a thruster that cannot fire
    is 0, so it is never chosen). The same forces as the fixed supports' code on the same
    numbers; compiled only for scenes with a vehicle's thrusters (their availability varies)."""
    n, m = F.shape[0], V.shape[1]
    for k in range(m):
        s, any_k = NO_SHIFT, 0.0
        for i in range(n):
            pos = V[i, k] > 0.0
            s = ca.fmax(s, ca.if_else(pos, -F[i] / ca.if_else(pos, V[i, k], 1.0), NO_SHIFT))
            any_k = ca.fmax(any_k, ca.if_else(pos, 1.0, 0.0))
        F = F + ca.if_else(any_k > 0.5, s, 0.0) * V[:, k]
    F = ca.fmax(F, 0.0)
    kk = 1.0
    for i in range(n):
        kk = ca.fmax(kk, F[i] / f_max[i])
    return F / kk


def map_lp(D, G, f_max, L, weights, pure: bool):
    """Forces in ``[0, F_max]`` delivering ``L`` exactly (and no net force when ``pure``) with the
    least ``Σ w_i F_i`` (``w = 1 / Isp``: least propellant), by scipy's HiGHS; None when
    infeasible (the caller then uses :func:`map_min_norm_shift`)."""
    from scipy.optimize import linprog

    A = np.vstack([D, G]) if pure else D
    b = np.concatenate([L, np.zeros(3)]) if pure else np.asarray(L, dtype=float)
    res = linprog(weights, A_eq=A, b_eq=b, bounds=list(zip(np.zeros(len(f_max)), f_max)), method="highs")
    return res.x if res.status == 0 else None


@register_actuator
class ThrusterCluster(Actuator):
    """All the scene's ``[[thruster]]`` tables with the ``[thrusters]`` options (module docstring).

    Parameters
    ----------
    scene : Scene
        The truth flown (thruster torques about its mass centre).
    known : Scene
        What flight software believes (the mapping's geometry).
    capacity_Nms : float
        The working CMG units' momentum capacity flight software knows [N m s].
    h_held_B : array_like, shape (3,), optional
        The rotor momentum of the CMG units flight software knows to have failed (held at their
        gimbal angles), B [N m s]: the dump law acts on the working units' ``h - h_held_B``.
    """

    kind = "thrusters"
    TABLE = "thruster"
    ORDER = 20

    def __init__(self, scene, known, capacity_Nms: float, h_held_B=None):
        from ..scene.thrusters import ThrusterOptions

        self.scene, self.opt = scene, scene.thrusters or ThrusterOptions()
        #: the station's thrusters, then each vehicle's at each port it uses (scene/thrusters.py)
        self.thr, self.owners = flown_thrusters(scene), thruster_owners(scene)
        #: a vehicle's thrusters fly: each one's availability is a number (``avail``, 1 while docked)
        self.varying = any(o is not None for o in self.owners)
        self.n = len(self.thr)
        self.names = [t.name for t in self.thr]
        self.D, self.G = torque_arms(scene)
        self.known = known
        self.n_shift = self._shift_columns() if self.varying else 0
        self.c_known, self.M, self.V, self.pure = self._mapping(known)
        self.support = None if self.varying else supports(self.V)
        self.capacity = float(capacity_Nms)
        self.h_held = np.zeros(3) if h_held_B is None else np.asarray(h_held_B, dtype=float).reshape(3)
        self.f_max = np.array([t.force_N for t in self.thr])
        self.isp = np.array([t.isp_s for t in self.thr])
        #: the mode manager commands the mode (``[fdir]``, loop/fdir.py: its memory ``fdir_mode``)
        self.commanded = getattr(scene, "fdir", None) is not None
        #: the known cluster's geometry when the mode manager may declare a unit of a gimballed
        #: cluster (then the working units' momentum is summed from their gimbal angles:
        #: :meth:`_working_h`), else None
        geo = cmg_geometry(known.cmg) if self.commanded and getattr(known, "cmg", None) is not None else None
        self.cmg_geo = geo if geo is not None and geo.gimballed else None
        self.cmg_pc = self.cmg_geo.params(known.cmg) if self.cmg_geo is not None else np.zeros(0)
        super().__init__()

    @classmethod
    def present(cls, scene) -> bool:
        """Whether ``scene`` flies thrusters: its own or a vehicle's (from t = 0, every channel
        unavailable while its vehicle is away)."""
        return bool(flown_thrusters(scene))

    def _shift_columns(self) -> int:
        """The mapping's shift columns in every configuration of the run: the most opposed pairs
        among the thrusters that can fire in one (at least 1)."""
        out = 1
        for where in configuration_ports(self.scene):
            on = np.flatnonzero(available(self.owners, where))
            pairs = opposed_pairs([self.thr[i].position_B for i in on], [self.thr[i].unit_B for i in on])
            out = max(out, len(pairs or ()))
        return out

    def _mapping(self, known) -> tuple:
        """``(c_known, M, V, pure)``: flight software's mass centre [m] and mapping
        (:func:`mapping_matrices`) on the configuration ``known``. With a vehicle's thrusters,
        on those it knows can fire (the vehicles docked in ``known``), the others' rows 0 and V
        padded with zero columns to :meth:`_shift_columns` (the compiled shape of every
        configuration)."""
        D, G = torque_arms(known, base=self.scene)
        c = mass_centre_B(known)
        thr = flown_thrusters(known, self.scene)
        if not self.varying:
            pairs = opposed_pairs([t.position_B for t in thr], [t.unit_B for t in thr])
            return (c, *mapping_matrices(D, G, pairs))
        on = np.flatnonzero(available(self.owners, docked_at(known)))
        M, V, pure = np.zeros((self.n, 3)), np.zeros((self.n, self.n_shift)), False
        if on.size:
            pairs = opposed_pairs([thr[i].position_B for i in on], [thr[i].unit_B for i in on])
            M_on, V_on, pure = mapping_matrices(D[:, on], G[:, on], pairs)
            if V_on.shape[1] > self.n_shift:  # (a configuration the run's events do not make)
                raise ValueError(f"thrusters: the mapping on the configuration {docked_at(known)} needs "
                                 f"{V_on.shape[1]} shift vectors, the run's {self.n_shift}")
            M[on], V[on, :V_on.shape[1]] = M_on, V_on
        return c, M, V, pure

    def configuration_numbers(self, truth=None, known=None) -> dict[int, float]:
        """The numbers a configuration sets (:meth:`Actuator.configuration_numbers`): from
        ``truth`` each thruster's torque ``torque_B`` about its mass centre, from ``known`` the
        mapping's (``M``, ``V``, ``c_known``). ValueError when ``known``'s mapping has another
        structure (a pure couple, or which thrusters a shift moves: it shapes the compiled code)."""
        L = self.param_layout
        fields = {}
        if truth is not None:
            fields["torque_B"] = torque_arms(truth, base=self.scene)[0] * self.f_max
            if self.varying:  # the vehicles' thrusters fire while docked at their port
                fields["avail"] = available(self.owners, docked_at(truth))
        if known is not None:
            c, M, V, pure = self._mapping(known)
            if not self.varying and (pure != self.pure or V.shape != self.V.shape or supports(V) != self.support):
                raise ValueError(f"thrusters: the mapping on the configuration of mass centre {np.round(c, 6).tolist()} m "
                                 f"is {'a pure couple' if pure else 'not a pure couple'} with shifts moving "
                                 f"{supports(V)}, the run's {'is' if self.pure else 'is not'} with {self.support}: "
                                 "flight software cannot be told it mid-run (use update_after_s = \"never\")")
            fields.update(M=M, V=V, c_known=c)
        values = L.split(self.params)
        values.update(fields)
        new = L.pack(values)
        return {i: float(new[i]) for name in fields for i in range(L.slice(name).start, L.slice(name).stop)}

    def configuration_summary(self, truth) -> dict:
        """``thruster_no_torque_about`` of the configuration ``truth`` (:func:`no_torque_about`; none when off)."""
        return {} if self.opt.mode == "off" else {"thruster_no_torque_about": no_torque_about(self.scene, docked_at(truth))}

    @classmethod
    def from_scene(cls, scene, known, plant) -> "ThrusterCluster":
        """Flight software's mapping on ``known``, the dump law on the working units' capacity
        it knows (``plant.h_capacity``) and the failed units' held momentum it knows of."""
        cap = plant.h_capacity if plant.h_capacity is not None else math.inf
        return cls(scene, known, cap, held_momentum_B(known.cmg))

    @property
    def python_only(self) -> bool:
        return self.opt.mapping == "lp"

    @property
    def why(self) -> str:
        return "mapping = 'lp' runs scipy's HiGHS in Python each tick" if self.python_only else ""

    @staticmethod
    def summary_parts(s: dict) -> list[str]:
        """The run summary line's thruster parts (``stationbed run``), none without thrusters."""
        if "propellant_kg" not in s:
            return []
        per = f" ({s['propellant_kg_per_orbit']:.4g} kg per orbit)" if "propellant_kg_per_orbit" in s else ""
        out = [f"thrusters {s['thruster_firings']} firings, impulse {s['thruster_impulse_Ns']:.4g} N s, propellant "
               f"{s['propellant_kg']:.4g} kg{per}, {s['thruster_control_s']:g} s in thruster-only control"]
        if s.get("propellant_kg_by_vehicle"):
            out.append("by vehicle: " + ", ".join(f"{v} {kg:.4g} kg" for v, kg in s["propellant_kg_by_vehicle"].items()))
        out += no_torque_parts(s)
        if "thrusters_not_fused" in s:
            out.append(f"thrusters flown per tick: {s['thrusters_not_fused']}")
        return out

    @classmethod
    def columns(cls, scene) -> list[str]:
        """The CSV columns, values at the row's time t: the mode of the tick before t
        (``thr_mode`` 1 = thruster-only control, ``thr_dumping`` 1 = dumping), and totals over
        [0, t]: firings, time in thruster-only control [s], impulse Σ F t_on [N s], propellant
        [kg], and each thruster's on-time [s]."""
        thr = flown_thrusters(scene)
        if not thr:
            return []
        cols = ["thr_mode", "thr_dumping", "thr_firings", "thr_control_s", "thr_impulse_Ns", "thr_propellant_kg"]
        return cols + [f"thr_on_s_{t.name}" for t in thr]

    def row_index(self) -> np.ndarray:
        s = self.state
        idx = [s.slice(k).start for k in ("mode", "dumping", "firings", "control_s", "impulse_Ns", "propellant_kg")]
        return np.array(idx + list(range(s.size))[s.slice("on_total_s")], dtype=int)

    def summary(self, x) -> dict:
        """What the summary adds to the thruster metrics (``propellant_kg`` and the other totals
        are :data:`~stationbed.run.metrics.METRICS`, reduced from the rows' ``thr_*`` columns)."""
        out = {"thruster_mapping": self.opt.mapping, "thruster_pure_couple": bool(self.pure)}
        if self.scene.orbit is not None:  # for trajectory_metrics' propellant_kg_per_orbit
            out["orbit_period_s"] = 2.0 * math.pi / self.scene.orbit.mean_motion
        missing = self.configuration_summary(self.scene).get("thruster_no_torque_about", "")
        if missing and missing.count(",") < 5:  # an assist set that dumps about some axes only (all six: none can fire yet)
            out["thruster_no_torque_about"] = missing
        if self.varying:  # each vehicle's propellant (the totals count every thruster)
            kg = self.state.get(np.asarray(x, float), "on_total_s") * self.f_max / (self.isp * G0_M_S2)
            out["propellant_kg_by_vehicle"] = {v.name: float(sum(kg[i] for i, o in enumerate(self.owners)
                                                                 if o is not None and o[0] == v.name))
                                               for v in self.scene.vehicle if v.thruster}
        return out

    def command_numeric(self, t: float, h: float, x, r, tau_B):
        """One tick numerically: :meth:`command_lp` with ``mapping = "lp"``, else :meth:`command`."""
        return (self.command_lp if self.python_only else self.command)(t, h, x, r, tau_B)

    def _structure(self) -> tuple:
        # which thrusters each shift moves (it shapes the compiled code)
        shifts = hashlib.sha1(repr(self.support).encode()).hexdigest()[:8]
        cmg = (self.cmg_geo.kind, self.cmg_geo.n_units) if self.cmg_geo is not None else ()
        if self.varying:  # the supports are numbers (:func:`_masked_shift`); the valves' availability too
            shifts = f"avail{self.n_shift}"
        return (self.n, len(self.opt.inhibit), int(self.pure and not self.varying), int(self.opt.remainder),
                shifts) + (("fdir", *cmg) if self.commanded else ())

    def _layouts(self):
        n, ni = self.n, len(self.opt.inhibit)
        state = Layout(prev_on_s=n, acc_s=n, dumping=1, mode=1, on_total_s=n, firings=1, control_s=1,
                       impulse_Ns=1, propellant_kg=1)
        g = self.cmg_geo
        params = Layout(f_max=n, isp=n, min_on=n, torque_B=(3, n), M=(n, 3), V=self.V.shape, capacity=1, h_held=3, mode=1,
                        levels=2, assist=3, dump=2, hand=2, inhibit=max(2 * ni, 1), ok=n, leak=n, c_known=3,
                        **({"cmg_pc": g.n_par} if g is not None else {}), **({"avail": n} if self.varying else {}))
        outputs = Layout(request_B=3, force_N=n)
        # with [fdir]: its mode, the capacity it knows, and (a gimballed cluster) the gimbal angles
        # and each unit's declaration time (its memory ``t_unit``, -1: not declared)
        reads = {"fdir_mode": 1, "cmg_capacity": 1} if self.commanded else {}
        if g is not None:
            reads.update(gimbal=g.n_gimbals, t_unit=g.n_units)
        return state, params, outputs, Layout(h_B=3, **reads)

    def _n_channels(self) -> int:
        return self.n

    def _params(self) -> dict:
        o = self.opt
        more = {"avail": available(self.owners, docked_at(self.scene))} if self.varying else {}
        return dict(**more, f_max=self.f_max, isp=self.isp, min_on=[t.min_on_s for t in self.thr],
                    torque_B=self.D * self.f_max, M=self.M, V=self.V, capacity=self.capacity, h_held=self.h_held, mode=MODES[o.mode],
                    levels=[o.level_on, o.level_off], assist=[o.assist_on, o.dump_stop, o.h_min],
                    dump=[o.dump_time_s, o.max_dump_torque_Nm], hand=[o.handover, o.handback],
                    inhibit=[v for w in o.inhibit for v in w] or [0.0],
                    ok=np.ones(self.n), leak=np.zeros(self.n),  # the truth's valves (scheduled faults)
                    c_known=self.c_known,  # the mass centre the mapping is about (the LP's arms)
                    **({"cmg_pc": self.cmg_pc} if self.cmg_geo is not None else {}))  # the known cluster's numbers

    def _initial(self) -> dict:
        """Everything 0: CMG control, not dumping, nothing fired (``thruster_only``: its first
        tick sets the mode)."""
        return {k: np.zeros(self.state.shape(k)[0] * self.state.shape(k)[1]) for k in self.state.names}

    # -- the tick ---------------------------------------------------------------------------
    def _request(self, t, x, r, tau, p):
        """(mode, dumping, inhibited, L_dump, request): steps 1-2 of the module docstring."""
        h_B = self._working_h(r, p)
        hn = ca.norm_2(h_B)
        cap = self._capacity(r, p)
        f = hn / cap
        a_on, d_stop, h_min_f = p["assist"][0], p["assist"][1], p["assist"][2]
        mode_opt = self._mode_opt(r, p)
        m_prev = x["mode"]
        hand = ca.if_else(m_prev > 0.5, f > p["hand"][1], f >= p["hand"][0])
        mode = ca.if_else(mode_opt > 1.5, 0.0, ca.if_else(mode_opt > 0.5, 1.0, ca.if_else(hand, 1.0, 0.0)))
        dumping = ca.if_else(x["dumping"] > 0.5, f > d_stop, f >= a_on)
        dumping = ca.if_else(mode_opt > 1.5, 0.0, ca.if_else(dumping, 1.0, 0.0))
        h_min = h_min_f * cap
        excess = ca.fmax(hn - h_min, 0.0)
        dH = -excess / ca.fmax(hn, 1e-300) * h_B
        L = dH / p["dump"][0]
        Ln = ca.norm_2(L)
        L_dump = L * ca.fmin(1.0, p["dump"][1] / ca.fmax(Ln, 1e-300))
        inh = 0.0
        w = p["inhibit"]
        for k in range(len(self.opt.inhibit)):
            inh = ca.fmax(inh, ca.if_else(ca.logic_and(t >= w[2 * k], t < w[2 * k + 1]), 1.0, 0.0))
        req = (1.0 - inh) * (mode * tau + dumping * L_dump)
        return mode, dumping, inh, L_dump, req

    def _working_h(self, r, p):
        """The working units' momentum as flight software knows them, B [N m s]
        (:func:`~.working_momentum.working_momentum`): ``h_B`` less the held momentum of the
        units known failed from the start; with the mode manager (``[fdir]``) of a gimballed
        cluster, once it has declared a unit (its memory ``t_unit``), the sum over the units
        left at their measured gimbal angles."""
        g = self.cmg_geo
        if g is None:
            return r["h_B"] - p["h_held"]
        declared = [r["t_unit"][i] >= 0.0 for i in range(g.n_units)]
        return working_momentum(g, p["cmg_pc"], r["h_B"], p["h_held"], r["gimbal"], declared)

    def _capacity(self, r, p):
        """The working units' capacity flight software knows: the table's; with the mode manager
        (``[fdir]``), its memory ``cmg_capacity`` (the same number until a unit is declared)."""
        return r["cmg_capacity"] if self.commanded else p["capacity"]

    def _mode_opt(self, r, p):
        """The mode option of the tick (``MODES``' numbers): the table's; with the mode manager
        (``[fdir]``), from its mode: hold and drift ``off``, assist the table's, thruster_only."""
        if not self.commanded:
            return p["mode"]
        m = r["fdir_mode"]
        return ca.if_else(m < 0.5, MODES["off"], ca.if_else(m < 1.5, p["mode"], ca.if_else(m < 2.5, MODES["thruster_only"],
                                                                                           MODES["off"])))

    def _fire(self, t, h, x, F, p, inh, mode_opt=None):
        """On-times from the forces ``F`` (step 4): ``(on_s, acc_next)``."""
        n = self.n
        on, acc = [], []
        lv_on, lv_off = p["levels"][0], p["levels"][1]
        for i in range(n):
            want = F[i] / p["f_max"][i] * h + (x["acc_s"][i] if self.opt.remainder else 0.0)
            mn = p["min_on"][i]
            level = want / ca.fmax(mn, 1e-300)
            short = ca.if_else(level >= lv_on, mn, ca.if_else(level <= lv_off, 0.0,
                                                               ca.if_else(x["prev_on_s"][i] > 0.0, mn, 0.0)))
            t_on = ca.if_else(want >= mn, ca.fmin(want, h), short)
            t_on = ca.fmin(ca.fmax(t_on, 0.0), h) * (1.0 - inh) * ca.if_else((p["mode"] if mode_opt is None else mode_opt) > 1.5, 0.0, 1.0)
            on.append(t_on)
            keep = ca.if_else(F[i] > 0.0, 1.0, 0.0) * (1.0 - inh)
            acc.append(ca.fmin(ca.fmax((want - t_on) * keep, -h), h) if self.opt.remainder else ca.SX(0.0))
        return ca.vertcat(*on), ca.vertcat(*acc)

    def _finish(self, h, x, tau, p, mode, dumping, inh, L_dump, req, F, on, acc):
        """Steps 5-6: the CMGs' share, the ledger, the next state."""
        Tq = p["torque_B"]
        # the valves' truth (a scheduled fault, run/faults.py): stuck off (ok = 0) loses the
        # command, stuck on (leak = 1) fires the whole tick; healthy (1, 0): exactly the command
        on = [p["leak"][i] * h + (1.0 - p["leak"][i]) * p["ok"][i] * on[i] for i in range(self.n)]
        if self.varying:  # a vehicle's thruster fires only while it is docked at its port (avail = 1)
            on = [p["avail"][i] * on[i] for i in range(self.n)]
        on = ca.vertcat(*on)
        L_thr = ca.mtimes(Tq, on) / ca.fmax(h, 1e-300)
        rest = (1.0 - mode) * (tau - L_thr) - mode * dumping * (1.0 - inh) * L_dump
        fired = [ca.if_else(ca.logic_and(on[i] > 0.0, x["prev_on_s"][i] < h), 1.0, 0.0) for i in range(self.n)]
        imp = ca.dot(p["f_max"], on)
        prop = ca.dot(p["f_max"] / (p["isp"] * G0_M_S2), on)
        x_next = dict(prev_on_s=on, acc_s=acc, dumping=dumping, mode=mode, on_total_s=x["on_total_s"] + on,
                      firings=x["firings"] + sum(fired), control_s=x["control_s"] + mode * h,
                      impulse_Ns=x["impulse_Ns"] + imp, propellant_kg=x["propellant_kg"] + prop)
        return x_next, rest, on, Tq, dict(request_B=req, force_N=F)

    def _idle(self, t, x, r, tau, p):
        """True when this tick is certainly the identity (nothing fires, the request passes to
        the CMGs whole, the memory does not change): assist mode, CMG control, not dumping, |h|
        below both thresholds, no pulse or remainder pending. :meth:`_command` then gives
        exactly ``(x, tau, 0, torque_B)`` (every term it adds is an exact 0), so an executor may
        skip it (the fused loop does, behind a ``Function.if_else``)."""
        f = ca.norm_2(self._working_h(r, p)) / self._capacity(r, p)
        m = self._mode_opt(r, p)
        quiet = ca.logic_and(m < 0.5, ca.logic_and(x["mode"] < 0.5, x["dumping"] < 0.5))
        quiet = ca.logic_and(quiet, ca.logic_and(f < p["assist"][0], f < p["hand"][0]))
        pending = ca.sum1(ca.fabs(x["prev_on_s"])) + ca.sum1(ca.fabs(x["acc_s"]))
        idle = ca.logic_and(quiet, pending == 0)
        if self.commanded:  # off (hold, drift): idle once nothing is pending and control is the CMGs'
            idle = ca.logic_or(idle, ca.logic_and(m > 1.5, ca.logic_and(x["mode"] < 0.5, ca.logic_and(x["dumping"] < 0.5, pending == 0))))
        return ca.logic_and(idle, ca.sum1(p["leak"]) == 0)  # a leak fires: never idle

    def _command(self, t, h, x, r, tau, p):
        mode, dumping, inh, L_dump, req = self._request(t, x, r, tau, p)
        F = map_min_norm_shift(p["M"], p["V"], p["f_max"], req, self.support)
        on, acc = self._fire(t, h, x, F, p, inh, self._mode_opt(r, p))
        return self._finish(h, x, tau, p, mode, dumping, inh, L_dump, req, F, on, acc)

    # -- the LP path (per tick, Python) -------------------------------------------------------
    def lp_functions(self) -> tuple[ca.Function, ca.Function]:
        """``request(t, h, x, r, tau, p) -> (req, aux)`` and ``fire(t, h, x, tau, p, F, aux) ->
        (x_next, rest, on_s, torque_B, out)``: :meth:`_command` cut at the mapping, for
        ``mapping = "lp"`` (the forces come from :func:`map_lp` between the two)."""
        t, h = ca.SX.sym("t"), ca.SX.sym("h")
        x, r, p = self.state.symbol("x"), self.reads.symbol("r"), self.param_layout.symbol("p")
        tau, F, aux = ca.SX.sym("tau_B", 3), ca.SX.sym("F", self.n), ca.SX.sym("aux", 6)
        xs, ps = self.state.split(x), self.param_layout.split(p)
        mode, dumping, inh, L_dump, req = self._request(t, xs, self.reads.split(r), tau, ps)
        request = ca.Function("thr_request", [t, h, x, r, tau, p], [req, ca.vertcat(mode, dumping, inh, L_dump)])
        m, d, i, Ld = aux[0], aux[1], aux[2], aux[3:6]
        on, acc = self._fire(t, h, xs, F, ps, i)
        x_next, rest, on, Tq, out = self._finish(h, xs, tau, ps, m, d, i, Ld, ca.SX.zeros(3), F, on, acc)
        fire = ca.Function("thr_fire", [t, h, x, tau, p, F, aux],
                           [self.state.pack(x_next, symbolic=True), rest, on, ca.reshape(Tq, 3 * self.n, 1),
                            self.outputs.pack(out, symbolic=True)])
        return request, fire

    def command_lp(self, t: float, h: float, x, r, tau_B):
        """One tick with the LP mapping (numerically; falls back to min-norm-plus-shift when the
        request is infeasible within the thrusters' forces)."""
        if not hasattr(self, "_lp"):
            self._lp = self.lp_functions()
        request, fire = self._lp
        req, aux = (np.asarray(v).ravel() for v in request(t, h, x, r, tau_B, self.params))
        F = None
        L = self.param_layout
        if np.any(req != 0.0):  # on the configuration flight software was told of (its c_known)
            D_known, G_known = torque_arms(self.known, L.get(self.params, "c_known"))
            F = map_lp(D_known * self.f_max, G_known * self.f_max, np.ones(self.n), req, 1.0 / self.isp, self.pure)
            F = None if F is None else F * self.f_max
        if F is None:
            F = map_min_norm_shift(L.get(self.params, "M"), L.get(self.params, "V"), self.f_max, req)
        x_next, rest, on, Tq, out = (np.asarray(v).ravel() for v in fire(t, h, x, tau_B, self.params, F, aux))
        out[self.outputs.slice("request_B")] = req
        self.n_commands += 1
        return x_next, rest, on, Tq.reshape(self.n, 3).T, out
