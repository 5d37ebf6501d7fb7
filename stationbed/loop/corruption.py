"""The ideal measurement's noise (``[controller.sensor]``): a measurement-corruption plug-in.

``y_seen = corrupt(y, nz)``: the law's measurement ``y`` (its layout: ``run/measurement.py``)
with one tick's draws ``nz`` (:func:`draws_layout`: ``attitude`` 3, then ``rate`` 3, those on;
the values of ``rng.normal(0, sigma, 3)``): ``q_BN`` turned by the small rotation ``nz_att``
(``q ⊗ [1, nz_att / 2]``, renormalised), ``omega_BN_B + nz_rate``; the other fields untouched.

Written **once** as casadi expressions (:meth:`Corruption.symbolic`), composed as the ``noise``
block (:func:`~.block.corruption_block`): the fused loop inlines them in its compiled tick, the
per-tick loop's composed parts and the lockstep batch (those parts mapped) call them compiled;
the per-tick loop's generic path calls :meth:`Corruption.compiled`. There is no numpy twin.

It is not a :class:`~.sensor.Sensor`: a sensor samples the truth (:data:`~.sensor.TRUTH`) at its
own period and feeds the flight suite's estimator; this corrupts, every tick, what the law itself
sees (the whole measurement vector, gimbal angles included). The draws come from the run's one
``[controller.sensor]`` generator, per tick attitude then rate, served as the suite's are
(:meth:`Corruption.noise`: a :class:`~.flight.TickNoise` stream of a block of ticks at a time),
so a noisy run keeps its noise stream on every executor. The sensor *delay* is a block of its
own (:func:`~.block.delay_block`), composed before this one.
"""

from __future__ import annotations

from functools import lru_cache

import casadi as ca
import numpy as np

from ..core.compile import FastCall, compile_functions
from .flight import TickNoise
from .layout import Layout

__all__ = ["Corruption", "CorruptionNoise", "draws_layout", "corrupt_symbolic", "corrupt_compiled"]


@lru_cache(maxsize=None)
def draws_layout(attitude: bool, rate: bool) -> Layout:
    """One tick's draws, those on, in the per-tick loop's order: ``attitude`` (3: the small
    rotation applied to ``q_BN``), then ``rate`` (3, added to ``omega_BN_B``)."""
    return Layout(**({"attitude": 3} if attitude else {}), **({"rate": 3} if rate else {}))


def corrupt_symbolic(y, nz, flags, layout: Layout):
    """``y`` corrupted (``flags``: attitude on, rate on) by the draws ``nz`` (casadi SX or MX;
    scalar operations, so the compiled, the mapped and the inlined forms make the same IEEE
    operations in the same order)."""
    att, rate = flags
    N = draws_layout(att, rate)
    parts = [y[i] for i in range(y.numel())]
    if att:
        iq = layout.slice("q_BN")
        q = parts[iq]
        za = N.get(nz, "attitude")
        d = [0.5 * za[i] for i in range(3)]
        qn = [
            q[0] - q[1] * d[0] - q[2] * d[1] - q[3] * d[2],
            q[1] + q[0] * d[0] + q[2] * d[2] - q[3] * d[1],
            q[2] + q[0] * d[1] + q[3] * d[0] - q[1] * d[2],
            q[3] + q[0] * d[2] + q[1] * d[1] - q[2] * d[0],
        ]
        norm = ca.sqrt(qn[0] * qn[0] + qn[1] * qn[1] + qn[2] * qn[2] + qn[3] * qn[3])
        parts[iq] = [c / norm for c in qn]
    if rate:
        iw = layout.slice("omega_BN_B")
        zr = N.get(nz, "rate")
        parts[iw] = [w + zr[i] for i, w in enumerate(parts[iw])]
    return ca.vertcat(*parts)


@lru_cache(maxsize=None)
def _function(flags: tuple[bool, bool], layout: Layout) -> ca.Function:
    y = ca.SX.sym("y", layout.size)
    nz = ca.SX.sym("nz", draws_layout(*flags).size)
    return ca.Function("corrupt", [y, nz], [corrupt_symbolic(y, nz, flags, layout)], ["y", "nz"], ["y_seen"])


_COMPILED: dict = {}


def corrupt_compiled(flags: tuple[bool, bool], layout: Layout) -> FastCall:
    """``corrupt(y, nz) -> y_seen`` for ``flags`` generated as C (disk cache), bound as a
    :class:`FastCall` shared per flags and layout (its ``.f`` is the compiled Function)."""
    f = _function(tuple(flags), layout)
    hit = _COMPILED.get(id(f))
    if hit is None or hit[0] is not f:
        tag = f"corrupt{int(flags[0])}{int(flags[1])}_{layout.size}"
        lib = compile_functions([f], tag)[f.name()]
        hit = _COMPILED[id(f)] = (f, FastCall(lib))
    return hit[1]


class Corruption:
    """The corruption of one run's measurement (``[controller.sensor]``'s noise levels).

    Parameters
    ----------
    attitude_noise, rate_noise : float
        Standard deviations [rad], [rad/s] (0: that corruption off).
    layout : Layout
        The law's measurement layout (``q_BN`` and ``omega_BN_B`` among its fields).
    """

    def __init__(self, attitude_noise: float, rate_noise: float, layout: Layout):
        if attitude_noise < 0 or rate_noise < 0:
            raise ValueError(f"sensor noise must be non-negative, got {attitude_noise}, {rate_noise}")
        self.flags = (bool(attitude_noise > 0), bool(rate_noise > 0))
        self.layout = layout
        self.draws = draws_layout(*self.flags)
        sigma = {"attitude": float(attitude_noise), "rate": float(rate_noise)}
        self.sigma = self.draws.pack({f: [sigma[f]] * 3 for f in self.draws.names})

    @property
    def width(self) -> int:
        """Draws per tick."""
        return self.draws.size

    def symbolic(self, y, nz):
        """The corrupted measurement as casadi expressions of ``y`` and the draws ``nz`` (inline)."""
        return corrupt_symbolic(y, nz, self.flags, self.layout)

    def function(self) -> ca.Function:
        """``corrupt(y, nz) -> y_seen`` (shared per flags and layout)."""
        return _function(self.flags, self.layout)

    def compiled(self) -> FastCall:
        """:meth:`function` generated as C (disk cache), bound as a :class:`FastCall` (shared)."""
        return corrupt_compiled(self.flags, self.layout)

    def noise(self, rng: np.random.Generator, end: int | None = None):
        """The run's draws by tick from tick 0, from ``rng`` (the ``[controller.sensor]``
        generator): a :class:`~.flight.TickNoise` of :class:`CorruptionNoise` (``end``: the run's
        ticks, none drawn past them)."""
        return TickNoise(CorruptionNoise(self, rng), end)


class CorruptionNoise:
    """The draws of one run's corruption, tick chunk by tick chunk in order from tick 0 (the
    source of its :class:`~.flight.TickNoise` stream)."""

    def __init__(self, corruption: Corruption, rng: np.random.Generator):
        self.sigma, self.width = corruption.sigma, corruption.width
        self.rngs = {"noise": rng}
        self.next_tick = 0

    def draw(self, n: int, out: np.ndarray | None = None) -> np.ndarray:
        """The draws of the next ``n`` ticks, (n, width): per tick ``rng.normal(0, σ_att, 3)``
        then ``rng.normal(0, σ_rate, 3)`` (a Generator fills an array element by element from
        one stream, and ``normal(0, σ)`` is ``0 + σ z``: the same numbers from one
        ``standard_normal`` call); written into ``out`` when given."""
        z = 0.0 + self.sigma * self.rngs["noise"].standard_normal((n, self.width))
        self.next_tick += n
        if out is None:
            return z
        out[...] = z
        return out
