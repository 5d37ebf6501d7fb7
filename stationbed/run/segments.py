"""Where a run is cut: output times, the scene's discontinuities (where a torque kind's held part
jumps, array rate steps), and the input held over each smooth segment."""

from __future__ import annotations

import math

import numpy as np

from ..integrators import IntegrationError
from ..model import StationModel
from ..model.shadow_edges import shadow_edges
from ..model.torques import held_torque_B, torque_breakpoints
from ..scene import Scene

__all__ = [
    "output_times",
    "OutputTimes",
    "breakpoints",
    "smooth_cuts",
    "held_torque",
    "held_torque_from",
    "edge_ticks",
    "off_grid_ticks",
    "max_edges",
    "tick_edges",
    "tick_pieces",
    "torque_at",
    "close_chunk",
    "finish_chunks",
    "segment_input",
]


def output_times(duration: float, dt: float) -> np.ndarray:
    """Output times [s]: 0, every ``dt``, and ``duration`` (appended when it is not a multiple)."""
    clock = OutputTimes(duration, dt)
    return clock.times(0, len(clock))


class OutputTimes:
    """The times of :func:`output_times` without holding them (a run of millions of rows):
    time ``k`` is ``k * dt``, the last one ``duration`` (or the multiple within rounding of it).

    Parameters
    ----------
    duration, dt : float
        Run length and output step [s].
    """

    def __init__(self, duration: float, dt: float):
        n = int(math.floor(duration / dt + 1e-9))
        self.dt = dt
        last = n * dt
        if duration - last > 1e-9 * max(1.0, duration):
            self.count, self.last = n + 2, duration
        else:
            self.count, self.last = n + 1, min(last, duration)

    def __len__(self) -> int:
        return self.count

    def time(self, k: int) -> float:
        """Output time ``k`` [s]; ``inf`` past the last."""
        if k >= self.count:
            return math.inf
        return self.last if k == self.count - 1 else k * self.dt

    def times(self, k0: int, k1: int) -> np.ndarray:
        """Output times ``k0 .. k1 - 1`` [s], as :func:`output_times` gives them."""
        ts = np.arange(k0, k1) * self.dt
        if k1 == self.count and k1 > k0:
            ts[-1] = self.last
        return ts

    def first_after(self, t: float, strict: bool = True) -> int:
        """Index of the first output time after ``t`` (``>= t`` when not ``strict``); ``len`` if none."""
        k = min(max(0, int(t // self.dt) - 1), self.count)
        while k < self.count and (self.time(k) <= t if strict else self.time(k) < t):
            k += 1
        return k


def breakpoints(scene: Scene, duration: float) -> tuple[list[float], set[float]]:
    """Times where the scene is discontinuous, and the subset where array rates step (impulses)."""
    bps, steps = set(), set()
    for b in torque_breakpoints(scene):
        if 0.0 < b < duration:
            bps.add(float(b))
    for a in scene.appendage:
        for j in (a.alpha, a.beta):
            if not j.tracked:
                for st in j.rate_step:
                    if st.t < duration:
                        bps.add(float(st.t))
                        steps.add(float(st.t))
    return sorted(bps), steps


def smooth_cuts(scene: Scene, duration: float, integrator_cls) -> list[float]:
    """Extra cuts for an adaptive integrator's open-loop run: the times in (0, duration) where
    the shadow fraction has a kink or a jump (:func:`~stationbed.model.shadow_edges.shadow_edges`).
    The input does not jump there; cutting only spares the integrator stepping across the edge.
    Empty for a fixed-step integrator (its steps, and so its numbers, stay as they were)."""
    return shadow_edges(scene, duration) if integrator_cls.adaptive else []


def held_torque(scene: Scene, t_mid: float) -> np.ndarray:
    """The external torque held over the segment whose mid time is ``t_mid`` [s], B components
    [N m], shape (3,): every torque kind's held part (:func:`~stationbed.model.torques.held_torque_B`)."""
    return held_torque_B(scene, t_mid)


def held_torque_from(scene: Scene, t: float, bps, duration: float) -> np.ndarray:
    """The external torque held over the smooth stretch that *starts* at ``t`` [s]: from ``t`` to
    the first breakpoint after it (``bps``, sorted, from :func:`breakpoints`) or to ``duration``.

    What an executor that carries the held torque from tick to tick (the closed loop's fused
    tick, the fused loop) must hold after integrating up to ``t``. Taking the value of the
    segment that *ended* at ``t`` instead is issue 19's window bug: with an edge exactly on a
    tick boundary no segment starts at the edge, so the value before it was carried past it.
    B components [N m], shape (3,)."""
    end = next((b for b in bps if b > t), max(duration, t))
    return held_torque(scene, 0.5 * (t + end) if end > t else t)


def segment_input(scene: Scene, model: StationModel, a: float, b: float, u: np.ndarray) -> None:
    """Set the held input of the smooth segment [a, b] in place: the external torque held over it
    and, when the scene has array rate steps, the segment's time that decides their side."""
    t_mid = 0.5 * (a + b)
    lay = model.input_layout
    u[lay.slice("u_ext")] = held_torque(scene, t_mid)
    if "t_step" in lay:
        u[lay.slice("t_step")] = t_mid


def edge_ticks(comp) -> list[int] | None:
    """The ticks k (``t = k * period`` exactly, as the loop's clock computes it) where a fused
    loop cuts its chunk: the discontinuities on the tick grid, its scheduled steps (run/schedule.py:
    always on the grid), and each tick holding a discontinuity between ticks with the tick after
    it (that tick is a piece of its own, its step split at the edge: :func:`tick_edges`); None
    when the scene has array rate steps (the state jumps there: the per-tick loop's generic path)."""
    inside = [b for b in comp.bps if 0.0 < b < comp.duration]
    if inside and comp.model.has_steps:
        return None
    K = comp.ticks()
    ks = {round(b / comp.period) for b in inside if round(b / comp.period) * comp.period == b}
    for k in off_grid_ticks(comp):
        ks |= {k, k + 1}
    return sorted({k for k in ks | set(comp.schedule.ticks) if 0 < k < K})


def off_grid_ticks(comp) -> dict[int, list[float]]:
    """The ticks that hold a discontinuity of the scene strictly inside them (the per-tick
    loop's ``t_k < b < t_k+1``, ``t_k = k * period``, the last tick ending at the duration):
    tick -> its breakpoints [s], sorted."""
    period, duration = comp.period, comp.duration
    out: dict[int, list[float]] = {}
    for b in comp.bps:
        if not 0.0 < b < duration:
            continue
        k = int(b // period)
        while k > 0 and k * period >= b:
            k -= 1
        while min((k + 1) * period, duration) <= b:
            k += 1
        if k * period < b:
            out.setdefault(k, []).append(float(b))
    return {k: sorted(v) for k, v in sorted(out.items())}


def max_edges(comp) -> int:
    """The most scene breakpoints inside one tick of the run (0: every edge on the grid): the
    size of an edge tick's compiled case (:func:`tick_edges`)."""
    return max((len(v) for v in off_grid_ticks(comp).values()), default=0)


def tick_edges(comp, k: int, h: float, n: int) -> np.ndarray | None:
    """The edges inside tick ``k`` of length ``h`` [s] as an edge tick's parameters (the composed
    ``edge``, :func:`~stationbed.loop.actuator.split_step`), or None when the tick holds none:
    ``n`` times into the tick [s] then ``n`` jumps of the held external torque (3 each, B
    components [N m]: the torque held after the edge less the one before, :func:`held_torque_from`),
    padded with edges at ``h`` that change nothing. The tick's own held torque is the one held
    from its start (the executors set it)."""
    bs = off_grid_ticks(comp).get(k)
    if not bs:
        return None
    t0 = k * comp.period
    e, du = np.full(n, h), np.zeros((n, 3))
    prev = held_torque_from(comp.scene, t0, comp.bps, comp.duration)
    for j, b in enumerate(bs):
        nxt = held_torque_from(comp.scene, b, comp.bps, comp.duration)
        e[j], du[j] = b - t0, nxt - prev
        prev = nxt
    return np.concatenate([e, du.ravel()])


def tick_pieces(k: int, n_act: int, edges, duration: float, period: float) -> list[tuple[int, int, float]]:
    """The compiled calls that advance ticks ``k .. k + n_act - 1`` of a fused loop: ``(a, b, h)``
    runs ticks a..b-1 of length h [s]. One call per stretch of held torque (an edge tick in
    ``edges`` on the grid splits the chunk, each stretch holding the torque of the stretch that
    starts there, :func:`held_torque_from`), and a final period shorter than ``period`` on its own."""
    last_len = duration - (k + n_act - 1) * period  # the final period may be shorter
    n_full = n_act - 1 if last_len < period * (1 - 1e-12) else n_act
    cuts = [k] + [e for e in edges if k < e < k + n_full] + [k + n_full]
    pieces = [(a, b, period) for a, b in zip(cuts[:-1], cuts[1:]) if b > a]
    if n_full < n_act:  # the short final period
        pieces.append((k + n_full, k + n_act, last_len))
    return pieces


def torque_at(comp, edges, u_ext):
    """``torque_at(t)`` for :func:`run_pieces`: the external torque held from ``t``
    (:func:`held_torque_from`) where the run of ``comp`` has edges on the grid (``edges``,
    :func:`edge_ticks`), else the run's one held torque ``u_ext`` (nothing to look up)."""
    if edges:
        return lambda t: held_torque_from(comp.scene, t, comp.bps, comp.duration)
    return lambda t: u_ext


def run_pieces(chunk, C, P, pieces, k: int, period: float, torque_at, draws=None, step=None, edge=None) -> np.ndarray:
    """Advance a fused loop's chunk over the :func:`tick_pieces` of a row starting at tick ``k``,
    one compiled call each (run/composed.py).

    ``chunk`` is the compiled chunk (a FastCall: carry, parameters[, each tick's draws]); its carry
    input (layout ``C``: ``i``, ``counts``, ...) holds the carry at tick ``k`` and, after, the
    carry at the row's end. Each piece sets the parameters (layout ``P``: ``t0``, ``h``, ``n_act``,
    ``k0`` where it has one, ``u_ext`` = ``torque_at(t0)``) and ``draws[a - k : b - k]`` (the
    rows' ticks, tick by tick); ``step(a)``, when given, applies the scheduled steps at a piece's
    first tick ``a`` (run/schedule.py) to the carry and the parameters. ``edge``, when given,
    ``(edge_chunk, edges_of)``: a piece whose ``edges_of(a, h)`` is not None (a tick holding a
    discontinuity, a piece of its own: :func:`edge_ticks`) runs the edge tick's compiled case
    ``edge_chunk`` (one tick; the parameters then those edges). Returns the pieces'
    rate-limited and saturated tick counts."""
    c0, par = chunk.args[0], chunk.args[1]
    ci, cc = C.slice("i"), C.slice("counts")
    pt0, ph, pn, pu = (P.slice(f) for f in ("t0", "h", "n_act", "u_ext"))
    pk = P.slice("k0") if "k0" in P else None
    counts = np.zeros(2)
    for a, b, h in pieces:
        if step is not None:
            step(a)
        c0[ci], c0[cc] = 0.0, 0.0
        par[pt0], par[ph], par[pn] = a * period, h, b - a
        if pk is not None:
            par[pk] = a
        par[pu] = torque_at(a * period)
        if draws is not None:  # column-major (width, n): tick by tick
            chunk.args[2][: draws.shape[1] * (b - a)] = draws[a - k : b - k].ravel()
        e = None if edge is None else edge[1](a, h)
        if e is not None:  # the edge tick's case: the same carry, parameters and draws, then the edges
            fe = edge[0]
            fe.args[0][:] = c0
            fe.args[1][: len(par)] = par
            fe.args[1][len(par):] = e
            if draws is not None:
                fe.args[2][:] = chunk.args[2][: draws.shape[1]]
            fe()
            rc = fe.res[0]
        else:
            chunk()
            rc = chunk.res[0]
        counts += rc[cc]
        c0[:] = rc
    return counts


def close_chunk(res, ticks: int, counts, lim: int, sat: int, x, t_end: float) -> int:
    """After a compiled chunk of the fused loop (run/composed.py):
    hand its rate-limited and saturated ticks (``counts``) back to the run's
    :class:`~.composition.RunState` ``res``, stop with IntegrationError at ``t_end`` when the
    state ``x`` is not finite (``res.ticks`` set to the ``ticks`` run), and return the next
    row's flag: saturation in the chunk's ticks after the row tick (whose own ``lim``/``sat``
    its row reported) goes into the next row, as the per-tick loop does (a row reports the
    ticks since the previous row)."""
    res.count(counts[0], counts[1])
    if not np.all(np.isfinite(x)):
        res.ticks = ticks
        raise IntegrationError(t_end, "state is not finite (NaN or inf)")
    return int((counts[0] - lim) + (counts[1] - sat) > 0.5)


def finish_chunks(res, x, ticks: int) -> None:
    """The fused loops' end (also after a failure): the final state ``x`` and the ``ticks`` run
    handed back (:meth:`~.composition.RunState.end`: the law's compiled updates, the ticks and
    the last row's, the integrator's steps, the rows flushed)."""
    res.end(x, ticks)
