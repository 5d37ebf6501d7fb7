"""The actuator plug-in: its contract (:class:`Actuator`), its registry (:data:`ACTUATORS`) and
the integration of its pulses over a control period (:func:`pulse_pieces`, :func:`split_step`).

An actuator turns the law's torque request into what acts on the plant over one control period
``[t, t + h]``; it is written **once** as casadi expressions,

``(x_next, tau_rest_B, on_s, torque_B, out) = command(t, h, x, r, tau_B, p)``

* ``x`` its memory (``STATE``), ``p`` its numbers (``PARAMS``), ``r`` the measurement fields it
  reads (``READS``, a :class:`~.layout.Layout` of the run's measurement names, e.g. ``h_B``);
* ``tau_B`` the torque the law requests (B components [N m]);
* ``tau_rest_B`` the part of the request it leaves to the next actuator of the chain (the last
  one, the CMG cluster or the ideal torquer, takes all it is given);
* ``on_s`` (``n_channels``): channel j acts over ``[t, t + on_s[j]]``, ``0 <= on_s[j] <= h``;
* ``torque_B`` (3 x ``n_channels``, column j = channel j's torque on B while on [N m]);
* ``out`` its reported values (``OUTPUTS``).

The executors add the channels that are on to the plant's external torque and **split the
integration at every edge** ``t + on_s[j]`` (:func:`pulse_pieces` per tick in Python,
:func:`split_step` in the compiled tick): no averaging, so a channel's impulse is exactly
``torque_B[:, j] * on_s[j]`` (to round-off). Both evaluate the same casadi function
(:meth:`Actuator.function`, as a block of the composed tick: loop/block.py). There is no numpy twin.

How the existing actuators read in this contract (docs/loop.md, "Actuators"): the ideal torquer
is one channel with ``on_s = h`` and ``torque_B = tau_B`` (``tau_rest_B = 0``); the CMG cluster
has no channel: it is an *internal* actuator whose command sets the plant's held CMG input
(``u_cmg``, the steering law's gimbal rates), and it is the end of the chain (it takes
``tau_rest_B``). Both are plug-ins (loop/cmg_cluster.py: ``IdealTorquer``, ``CmgClusterActuator``,
declaring ``FULL_TICK`` and ``INTERNAL`` / ``HELD``); the thrusters were the first.
"""

from __future__ import annotations

from typing import ClassVar

import casadi as ca
import numpy as np

from ..core.compile import FastCall, compile_functions
from .layout import Layout

__all__ = ["Actuator", "ACTUATORS", "get_actuator", "register_actuator", "pulse_pieces", "split_step", "chain_kinds",
           "TRUE_SUFFIX"]

#: a ``READS`` name ending so reads the plant's true measurement (rule 2)
TRUE_SUFFIX = "_true"


class Actuator:
    """Base class of an actuator kind (one instance per scene's set of its tables).

    The public methods check and count; the plug-in writes the private ones. Rules for
    implementers:

    1. Set ``kind`` (the registry key in :data:`ACTUATORS`).
    2. Declare ``STATE``, ``PARAMS``, ``OUTPUTS`` and ``READS`` as :class:`Layout` attributes,
       or write ``_layouts()`` when their shape depends on the scene (the number of thrusters),
       returning the shape-setting numbers from ``_structure()``. ``READS`` names fields of
       the run's measurement (the Layout ``stationbed.run.measurement.measurement_fields``;
       :meth:`Actuator.reads_in` finds them there by name): what the law sees (the estimate
       with an ``[estimator]``). A name ending in ``_true`` reads that field of the plant's
       *true* measurement (``q_BN_true``: the attitude flown): the physics of what the
       actuator makes (a magnetic torque ``m × B`` in the true field), never its decisions;
       the actuator sees nothing else of the plant.
    3. Set ``n_channels`` (or write ``_n_channels()``), the pulse channels.
    4. Write ``_params()`` (every ``PARAMS`` field by name) and ``_initial()`` (every ``STATE``
       field at t = 0). Numbers are inputs of the compiled function, never constants in it.
    5. Write ``_command(t, h, x, r, tau_B, p)`` with casadi only (``ca.if_else``, no Python
       ``if`` on a symbol); ``x``, ``r``, ``p`` arrive as dicts of fields. Return
       ``(x_next, tau_rest_B, on_s, torque_B, out)``: dicts for ``x_next`` and ``out`` by
       ``STATE`` / ``OUTPUTS`` names, ``on_s`` a column of ``n_channels`` in ``[0, h]``,
       ``torque_B`` a (3, n_channels) matrix.
    6. Prove it in a test against an independent truth (closed form, a hand-worked sequence,
       the momentum balance with the pulse edges inside ticks).
    7. Optionally write ``_idle(t, x, r, tau_B, p)``: a casadi condition under which
       ``_command`` is exactly ``(x, tau_B, 0, torque_B)``; an executor may then skip the
       command (the fused loop does). It must be exact, not approximate: executors that do not
       skip must give the same numbers.
    8. Optionally declare ``FULL_TICK = True`` when every channel is on for the whole tick
       (``on_s = h`` identically): an executor may then add ``torque_B`` to the held torque
       without splitting the step (no edge inside the tick; the same numbers). Declare
       ``INTERNAL = True`` for an actuator that is part of the plant (it reads the plant's
       truth: ``READS`` names fields of the formulation's state layout or the true rate), and
       ``HELD = "<name>"`` when the ``OUTPUTS`` field of that name is the model's held input of
       the same name (``model.input_layout``, e.g. the CMG cluster's ``u_cmg``).
    9. Declare where it sits in the run: ``TABLE``, the scene field holding its tables (the
       chain has the kind when that field is set and not empty, or override ``present(scene)``
       as the thrusters do: a visiting vehicle's tables count); ``ORDER``, its place in the
       chain (lower first: what costs nothing takes its part of the request first); and
       write ``from_scene(scene, known, plant)`` (the truth flown, what flight software
       knows, the law's plant facts). Optionally ``ROW_COLUMNS`` (CSV column -> ``(STATE
       field, index)``, the memory before each row's tick) or ``columns(scene)`` and
       ``row_index()``, and ``summary(x)`` (what the run summary adds from the memory ``x``
       at the end). ``python_only`` (with ``why``) keeps a run per tick.
    10. Optionally write ``configuration_numbers(truth, known)`` when some of its numbers
        depend on the station's mass properties (the thrusters' arms about the composite mass
        centre): a docking or undocking sets them as a step, the compiled code unchanged; and
        ``configuration_summary(truth)`` when the summary should say something of each
        configuration the run flies (the thrusters' axes without torque): each docking event's
        entry of the summary's ``events`` carries it.
    """

    kind: ClassVar[str] = ""
    STATE: ClassVar[Layout | None] = None
    PARAMS: ClassVar[Layout | None] = None
    OUTPUTS: ClassVar[Layout | None] = None
    READS: ClassVar[Layout | None] = None
    n_channels: int = 0
    FULL_TICK: ClassVar[bool] = False  #: rule 8: every channel on for the whole tick
    INTERNAL: ClassVar[bool] = False  #: rule 8: part of the plant, reads its truth
    HELD: ClassVar[str | None] = None  #: rule 8: the OUTPUTS field that is the model's held input
    TABLE: ClassVar[str] = ""  #: rule 9: the scene field holding its tables ("" for the chain's end)
    ORDER: ClassVar[int] = 0  #: rule 9: its place in the chain, lower first
    ROW_COLUMNS: ClassVar[dict] = {}  #: rule 9: CSV column -> (STATE field, index)
    python_only: bool = False  #: rule 9: True when it runs in Python each tick (then ``why``)
    why: str = ""

    _functions: ClassVar[dict] = {}
    _compiled: ClassVar[dict] = {}

    def __init__(self):
        self.state, self.param_layout, self.outputs, self.reads = self._layouts()
        self.n_channels = self._n_channels()
        self.params = self.param_layout.pack(self._params())
        self.x0 = self.state.pack(self._initial())
        self.n_commands = 0

    # -- where it sits in a run (rule 9) ---------------------------------------------------
    @classmethod
    def present(cls, scene) -> bool:
        """Whether ``scene`` flies this kind (its ``TABLE`` set and not empty)."""
        return bool(cls.TABLE) and bool(getattr(scene, cls.TABLE, None))

    @classmethod
    def from_scene(cls, scene, known, plant) -> "Actuator":
        """This kind for ``scene`` (the truth flown), ``known`` (what flight software knows) and
        ``plant`` (the law's plant facts)."""
        raise NotImplementedError

    @classmethod
    def columns(cls, scene) -> list[str]:
        """Its CSV columns in ``scene``'s runs (the memory before each row's tick)."""
        return list(cls.ROW_COLUMNS)

    @staticmethod
    def summary_parts(s: dict) -> list[str]:
        """The run summary line's parts for this kind (``stationbed run``), from the run's
        summary ``s``; none when the run has none of it (the default: no parts)."""
        return []

    def row_index(self) -> np.ndarray:
        """The indices in its memory of the values a row reports (:meth:`columns`' order)."""
        return np.array([self.state.slice(f).start + i for f, i in self.ROW_COLUMNS.values()], dtype=int)

    def summary(self, x: np.ndarray) -> dict:
        """What the run's summary adds from its memory ``x`` at the end of the run."""
        return {}

    def configuration_numbers(self, truth=None, known=None) -> dict[int, float]:
        """``{index in its numbers: value}`` of the numbers that depend on the station's
        configuration (rule 10): those of the truth flown, from the scene ``truth``, and those
        flight software knows, from ``known`` (either None: left out). A docking event sets the
        truth's at its tick and the knowledge's when flight software is told (run/docking.py).
        None by default (a kind whose numbers do not depend on the mass properties)."""
        return {}

    def configuration_summary(self, truth) -> dict:
        """What the summary's entry of a docking event says of the configuration after it, the
        scene ``truth`` (run/docking.py). None by default."""
        return {}

    # -- declarations -------------------------------------------------------------------
    def _layouts(self) -> tuple[Layout, Layout, Layout, Layout]:
        return self.STATE, self.PARAMS, self.OUTPUTS, self.READS

    def _n_channels(self) -> int:
        return type(self).n_channels

    def _structure(self) -> tuple:
        return ()

    @property
    def key(self) -> str:
        """The name of this kind's compiled function for this instance's structure."""
        extra = "_".join(str(s) for s in self._structure())
        return f"actuator_{self.kind}" + (f"_{extra}" if extra else "")

    def reads_in(self, layout: Layout) -> slice | np.ndarray:
        """Where this actuator's ``READS`` fields lie in a vector of ``layout`` (the run's
        measurement), in ``READS`` order, by name: a slice when they are contiguous there, else
        the indices. A ``<field>_true`` name (rule 2) lies in the true measurement, appended
        after what the law sees: ``concatenate([y_seen, y_true])[reads_in(layout)]``. KeyError
        naming a field the layout lacks; ValueError on a size mismatch."""
        at = np.arange(layout.size)
        parts = []
        for name in self.reads.names:
            true = name.endswith(TRUE_SUFFIX)
            idx = at[layout.slice(name[: -len(TRUE_SUFFIX)] if true else name)] + (layout.size if true else 0)
            if idx.size != self.reads.slice(name).stop - self.reads.slice(name).start:
                raise ValueError(f"actuator {self.kind!r} reads {name!r} of size {self.reads.shape(name)}, "
                                 f"the measurement's has {idx.size}")
            parts.append(idx)
        idx = np.concatenate(parts) if parts else np.zeros(0, dtype=int)
        if idx.size and np.array_equal(idx, np.arange(idx[0], idx[0] + idx.size)):
            return slice(int(idx[0]), int(idx[0]) + idx.size)
        return idx

    # -- the one expression ----------------------------------------------------------------
    def function(self) -> ca.Function:
        """``(t, h, x, r, tau_B, p) -> (x_next, tau_rest_B, on_s, torque_B, out)``, casadi SX
        (``torque_B`` flattened column-major, 3 per channel); built once per kind and structure."""
        f = Actuator._functions.get((type(self), self.key))
        if f is None:
            t, h = ca.SX.sym("t"), ca.SX.sym("h")
            x, r, p = self.state.symbol("x"), self.reads.symbol("r"), self.param_layout.symbol("p")
            tau = ca.SX.sym("tau_B", 3)
            x_next, rest, on_s, torque_B, out = self._command(t, h, self.state.split(x), self.reads.split(r), tau,
                                                              self.param_layout.split(p))
            f = ca.Function(self.key, [t, h, x, r, tau, p],
                            [self.state.pack(x_next, symbolic=True), ca.vertcat(rest), ca.vertcat(on_s),
                             ca.reshape(torque_B, 3 * self.n_channels, 1), self.outputs.pack(out, symbolic=True)],
                            ["t", "h", "x", "r", "tau_B", "p"], ["x_next", "tau_rest_B", "on_s", "torque_B", "out"],
                            {"cse": True})
            Actuator._functions[(type(self), self.key)] = f
        return f

    def compiled(self) -> FastCall:
        """The same function generated as C, compiled, with bound buffers (one per kind and structure)."""
        fc = Actuator._compiled.get((type(self), self.key))
        if fc is None:
            fc = Actuator._compiled[(type(self), self.key)] = FastCall(compile_functions([self.function()], self.key)[self.key])
        return fc

    def idle_function(self) -> ca.Function | None:
        """``(t, x, r, tau_B, p) -> idle`` when the plug-in writes ``_idle`` (rule 7), else None."""
        if type(self)._idle is Actuator._idle:
            return None
        t = ca.SX.sym("t")
        x, r, p = self.state.symbol("x"), self.reads.symbol("r"), self.param_layout.symbol("p")
        tau = ca.SX.sym("tau_B", 3)
        idle = self._idle(t, self.state.split(x), self.reads.split(r), tau, self.param_layout.split(p))
        return ca.Function(f"{self.key}_idle", [t, x, r, tau, p], [idle])

    def command_numeric(self, t: float, h: float, x: np.ndarray, r: np.ndarray, tau_B: np.ndarray):
        """One tick as a per-tick executor runs it: :meth:`command` (a ``python_only`` kind
        writes its own)."""
        return self.command(t, h, x, r, tau_B)

    def command(self, t: float, h: float, x: np.ndarray, r: np.ndarray, tau_B: np.ndarray):
        """One tick, numerically (compiled): ``(x_next, tau_rest_B, on_s, torque_B (3, n), out)``."""
        if not 0.0 <= h:
            raise ValueError(f"actuator {self.kind!r}: tick length h = {h!r} must be >= 0")
        fc = self.compiled()
        for arg, v in zip(fc.args, (t, h, x, r, tau_B, self.params)):
            arg[:] = v
        fc()
        self.n_commands += 1
        res = fc.res
        return (res[0].copy(), res[1].copy(), res[2].copy(), res[3].reshape(self.n_channels, 3).T.copy(),
                res[4].copy())

    # -- written by the plug-in -----------------------------------------------------------
    def _params(self) -> dict:
        raise NotImplementedError

    def _initial(self) -> dict:
        raise NotImplementedError

    def _command(self, t, h, x: dict, r: dict, tau_B, p: dict):
        raise NotImplementedError

    def _idle(self, t, x: dict, r: dict, tau_B, p: dict):
        raise NotImplementedError


#: ``kind`` -> its class; a new kind is one file in loop/ and one :func:`register_actuator` call
ACTUATORS: dict[str, type[Actuator]] = {}


def register_actuator(cls: type[Actuator]) -> type[Actuator]:
    """Register ``cls`` under ``cls.kind`` (a class decorator)."""
    if not cls.kind:
        raise ValueError(f"{cls.__name__} declares no kind")
    ACTUATORS[cls.kind] = cls
    return cls


def chain_kinds(scene) -> list[type[Actuator]]:
    """The registered kinds ``scene`` flies before the chain's end, in chain order (``ORDER``,
    then the kind's name)."""
    return sorted((c for c in ACTUATORS.values() if c.present(scene)), key=lambda c: (c.ORDER, c.kind))


def get_actuator(kind: str | type[Actuator]) -> type[Actuator]:
    """The class of an actuator kind, by name or the class itself (any subclass)."""
    if isinstance(kind, type) and issubclass(kind, Actuator):
        return kind
    try:
        return ACTUATORS[kind]
    except (KeyError, TypeError):
        raise ValueError(f"unknown actuator kind {kind!r}; valid kinds: {', '.join(sorted(ACTUATORS))}") from None


# -- integrating pulses exactly ----------------------------------------------------------------
def pulse_pieces(on_s: np.ndarray, h: float) -> list[tuple[float, float, np.ndarray]]:
    """The pieces of a tick ``[0, h]`` between the pulse edges: ``(a, b, on)`` with ``on`` the
    mask of the channels on over ``(a, b)`` (``on_s[j] > (a + b) / 2``, the rule
    :func:`split_step` compiles). Zero-length pieces are left out."""
    on_s = np.minimum(np.maximum(np.asarray(on_s, dtype=float), 0.0), h)
    edges = np.unique(np.concatenate(([0.0, h], on_s)))
    return [(a, b, on_s > 0.5 * (a + b)) for a, b in zip(edges[:-1], edges[1:]) if b > a]


def _sorted(v: list) -> list:
    """``v`` sorted ascending by an odd-even transposition network of fmin/fmax (no branch)."""
    v = list(v)
    n = len(v)
    for rnd in range(n):
        for i in range(rnd % 2, n - 1, 2):
            lo, hi = ca.fmin(v[i], v[i + 1]), ca.fmax(v[i], v[i + 1])
            v[i], v[i + 1] = lo, hi
    return v


def split_step(step, rhs, t, x, h, u, p, on_s, torque_B, u_layout: Layout | None = None, edge=None):
    """One tick of ``step`` (an integrator's ``explicit_step``) split at the pulse edges, casadi.

    ``on_s`` (n,) sorted (a branch-free network), pieces ``[e_j, e_j+1]`` from 0 to ``h``; over
    each, the channels with ``on_s > (e_j + e_j+1) / 2`` add their ``torque_B`` (3, n) column to
    the held external torque ``u_ext`` of ``u`` (by ``u_layout``, the model's ``input_layout``;
    None: ``u`` is ``u_ext`` alone). A zero-length piece is the identity (a step of 0).

    ``edge`` (4 m,), the scene's discontinuities inside the tick (an edge tick's case,
    :func:`~stationbed.run.segments.tick_edges`): ``m`` times into the tick, then ``m`` jumps of
    the held external torque (3 each); the tick is also cut there, and past edge ``i`` its jump
    is added (an edge at ``h`` with no jump changes nothing).
    """
    lay = Layout(u_ext=3) if u_layout is None else u_layout
    n = on_s.numel()
    on = [ca.fmin(ca.fmax(on_s[j], 0.0), h) for j in range(n)]
    m = 0 if edge is None else edge.numel() // 4
    es = [ca.fmin(ca.fmax(edge[i], 0.0), h) for i in range(m)]
    edges = [ca.SX(0.0) if isinstance(on_s, ca.SX) else 0.0] + _sorted(on + es) + [h]
    for a, b in zip(edges[:-1], edges[1:]):
        mid = 0.5 * (a + b)
        tq = 0
        for j in range(n):
            tq = tq + ca.if_else(on[j] > mid, 1.0, 0.0) * torque_B[:, j]
        u_ext = lay.get(u, "u_ext")
        for i in range(m):
            u_ext = u_ext + ca.if_else(es[i] < mid, 1.0, 0.0) * edge[m + 3 * i: m + 3 * i + 3]
        uj = lay.pack({**lay.split(u), "u_ext": u_ext + tq})
        x = step(rhs, t + a, x, b - a, uj, p)
    return x
