"""The sensors and the estimator of a scene as one composition on the executor's tick clock.

:class:`Suite` is what an executor runs: one casadi function per tick,

``(k, t, x, truth, w, p) -> (x_next, y)``

that steps every sensor whose sample falls on tick k (its period a whole number of ticks; tick k
is at ``t = k · tick``, the first sample of a sensor of period n ticks at tick n), holds the
others' last measurement, and steps the MEKF with the gyro's samples, telling it which heads are
new. The per-tick loop evaluates it compiled (one call per tick), the fused loop inlines it in
its ``mapaccum``; neither reads the other's internals. The state ``x``, noise ``w``, parameters
``p`` and outputs ``y`` are :class:`Layout` s named by the sensors (``STATE``, ``NOISE``,
``PARAMS``, ``OUTPUTS``).

Noise: sensor i (file order) draws one row of standard normals per sample of its own, from
``noise_rng(seed, i)``, in sample order; :class:`SuiteNoise` places them on the ticks where the
sensor samples. Drawn chunk by chunk in tick order, the numbers are those of one whole draw.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
from scipy.stats import chi2

from ..core.compile import FastCall, compile_functions
from .layout import Layout
from .mekf import Mekf
from .registry import build_sensors
from .sensor import TRUTH, noise_rng

__all__ = ["Suite", "SuiteNoise", "TICK_RATIO_TOL", "RESERVED"]

#: a sensor period that is a whole number of ticks to this relative tolerance is taken as one
TICK_RATIO_TOL = 1e-9
#: names of the suite's own fields (a sensor may not be called so)
RESERVED = frozenset({"mekf", "omega_hat_B", "q_BN_hat", "bias_B_hat", "gyro_pair"})
#: the redundant gyros' comparison's memory (issue 34 item 2c): consecutive samples over the
#: gate, declared (1), when [s] (-1: not), the gyro blamed (1 the filter's, 2 the spare)
PAIR = ("count", "declared", "t", "blamed")


class Suite:
    """The sensors (and the MEKF, when the tables name one) of a :class:`~stationbed.scene.Sensing`.

    Parameters
    ----------
    sensing : stationbed.scene.Sensing  The ``[[sensor]]`` tables and ``[estimator]``.
    tick : float  The executor's tick period [s] (the controller period).
    """

    def __init__(self, sensing, tick: float):
        self.sensing, self.tick = sensing, float(tick)
        self.sensors = build_sensors(sensing.sensor)
        self.every: dict[str, int] = {}
        for s in self.sensors:
            if s.name in RESERVED:
                raise ValueError(f"sensor '{s.name}': the name is taken by the estimator's outputs {sorted(RESERVED)}")
            ratio = s.period / self.tick
            if round(ratio) < 1 or abs(ratio - round(ratio)) > TICK_RATIO_TOL * ratio:
                raise ValueError(f"sensor '{s.name}': period {s.period:g} s is not a whole number of ticks "
                                 f"({self.tick:g} s)")
            self.every[s.name] = int(round(ratio))
        self.mekf = Mekf.from_sensors(sensing.estimator, self.sensors) if sensing.estimator is not None else None
        noisy = [s for s in self.sensors if s.n_noise]
        est = dict(mekf=self.mekf.state.size, omega_hat_B=3) if self.mekf else {}
        fd = getattr(sensing, "fdir", None)
        #: the redundant gyros compared (the filter's and its spare), or None (issue 34 item 2c)
        self.pair = (self.mekf.gyro, self.spare_gyro()) if self.spare_gyro() is not None and fd.gyro_pair_alpha else None
        if self.pair is not None:
            est["gyro_pair"] = len(PAIR)
        self.STATE = Layout(**{s.name: s.state.size for s in self.sensors},
                            **{f"{s.name}.y": s.outputs.size for s in self.sensors}, **est)
        self.NOISE = Layout(**{s.name: s.n_noise for s in noisy})
        self.PARAMS = Layout(**{s.name: s.param_layout.size for s in self.sensors},
                             **({"mekf": self.mekf.param_layout.size} if self.mekf else {}),
                             **({"gyro_pair": 2} if self.pair else {}))
        self.OUTPUTS = Layout(**{s.name: s.outputs.size for s in self.sensors},
                              **{f"{s.name}.fresh": 1 for s in self.sensors},
                              **(dict(q_BN_hat=4, bias_B_hat=3, omega_hat_B=3) if self.mekf else {}))
        self.params = self.PARAMS.pack({s.name: s.params for s in self.sensors},
                                       **({"mekf": self.mekf.params} if self.mekf else {}),
                                       **({"gyro_pair": [float(chi2.isf(fd.gyro_pair_alpha, 3)),
                                                         float(fd.gyro_pair_persistence)]} if self.pair else {}))
        self._f = self._compiled = self._plain = None
        self._records: dict = {}

    # -- state ----------------------------------------------------------------------------
    def initial(self, q_BN_hat=(1.0, 0.0, 0.0, 0.0), bias_B_hat=(0.0, 0.0, 0.0)) -> np.ndarray:
        """The suite's state at tick 0: each sensor's initial state, no measurement yet (zeros,
        a head's ``valid`` 0), the filter at the given estimates with its initial covariance."""
        v = {s.name: s.x0 for s in self.sensors}
        v.update({f"{s.name}.y": np.zeros(s.outputs.size) for s in self.sensors})
        if self.mekf:
            v.update(mekf=self.mekf.initial(q_BN_hat, bias_B_hat), omega_hat_B=np.zeros(3))
        if self.pair:
            v["gyro_pair"] = [0.0, 0.0, -1.0, 0.0]
        return self.STATE.pack(v)

    # -- the tick -------------------------------------------------------------------------
    def function(self) -> ca.Function:
        """``(k, t, x, truth, w, p) -> (x_next, y)``, one tick (see the module docstring).

        An MX function: each sensor's step and the filter's are ``Switch`` es on their tick
        (the sensor's own SX function when due, a hold when not), so generated code computes a
        sensor only on its samples (an SX ``if_else`` would compute both branches every tick)."""
        if self._f is None:
            self._f = self._build(plain=False)
        return self._f

    def plain_function(self) -> ca.Function | None:
        """:meth:`function` on a *plain* tick, as one SX function: a tick ``k > 0`` on which the
        sensors sampling every tick sample and no other does (a star tracker between its samples
        holds). The same operations as :meth:`function` on such a tick, without its switches,
        so that an executor can inline the whole tick in one SX graph (run/composed.py, loop/block.py sensing_block).
        None when a star-tracker head of the filter samples every tick (its update is the
        filter's switch).

        A tick is plain when :meth:`is_plain` says so."""
        if self._plain is None:
            self._plain = self._build(plain=True) or False
        return self._plain or None

    def is_plain(self, k):
        """Whether tick ``k`` (a casadi symbol or number) is plain: ``k > 0`` and no sensor
        sampling less often than every tick is due."""
        slow = [_due_on(k, e) for e in self.every.values() if e > 1]
        if not slow:
            return k > 0.5
        return ca.logic_and(k > 0.5, ca.logic_not(sum(slow[1:], slow[0]) > 0.5))

    def _build(self, plain: bool) -> ca.Function | None:
        """:meth:`function` (MX, each sensor and the filter behind its switch), or with ``plain``
        :meth:`plain_function` (SX: the every-tick sensors step, the others hold, the filter
        propagates alone; None where a filter's head samples every tick)."""
        m = self.mekf
        if plain and m is not None and any(self.every[h.name] == 1 for h in m.heads):
            return None
        cls = ca.SX if plain else ca.MX
        k, t = cls.sym("k"), cls.sym("t")
        x, truth = self.STATE.symbol("x", cls), TRUTH.symbol("truth", cls)
        w, p = self.NOISE.symbol("w", cls), self.PARAMS.symbol("p", cls)
        X, P = self.STATE.split(x), self.PARAMS.split(p)
        nxt, out, due = {}, {}, {}
        for s in self.sensors:
            e = self.every[s.name]
            due[s.name] = cls(float(e == 1)) if plain else _due_on(k, e)
            ws = self.NOISE.get(w, s.name) if s.name in self.NOISE else cls(0, 1)
            if not plain:
                step = _due(s.function(), f"{s.key}_tick")(due[s.name], t, X[s.name], X[f"{s.name}.y"], truth, ws, P[s.name])
            elif e == 1:
                step = s.function()(t, X[s.name], truth, ws, P[s.name])
            else:
                step = X[s.name], X[f"{s.name}.y"]
            nxt[s.name], nxt[f"{s.name}.y"] = step
            out[s.name], out[f"{s.name}.fresh"] = nxt[f"{s.name}.y"], due[s.name]
        if m:
            z = {"omega_B": out[m.gyro.name]}
            spare = self.spare_gyro()
            if spare is not None:  # the other gyro in once the filter has declared its own failed (issue 34)
                failed = m.state.get(X["mekf"], "gyro_fault") > 0.5
                if self.pair:  # ... unless the comparison blamed the spare
                    nxt["gyro_pair"] = self._compare(t, X, P, out, due[m.gyro.name])
                    failed = ca.logic_and(failed, ca.logic_not(ca.logic_and(X["gyro_pair"][1] > 0.5, X["gyro_pair"][3] > 1.5)))
                z["omega_B"] = ca.if_else(failed, out[spare.name], out[m.gyro.name])
            for i, h in enumerate(m.heads):
                z[f"q_SN_{i}"], z[f"valid_{i}"] = out[h.name][0:4], out[h.name][4]
                z[f"fresh_{i}"] = due[h.name]
            args = (X["mekf"], X["omega_hat_B"], m.inputs.pack(z, symbolic=True), P["mekf"])
            if not plain:
                nxt["mekf"], nxt["omega_hat_B"] = m.tick_function()(due[m.gyro.name], *args)
            elif self.every[m.gyro.name] == 1:
                nxt["mekf"], nxt["omega_hat_B"] = m.alone_function()(*args)
            else:
                nxt["mekf"], nxt["omega_hat_B"] = X["mekf"], X["omega_hat_B"]
            out.update(q_BN_hat=m.state.get(nxt["mekf"], "q_BN"), bias_B_hat=m.state.get(nxt["mekf"], "bias_B"),
                       omega_hat_B=nxt["omega_hat_B"])
        return ca.Function(f"suite_{len(self.sensors)}" + ("_plain" if plain else ""), [k, t, x, truth, w, p],
                           [self.STATE.pack(nxt, symbolic=True), self.OUTPUTS.pack(out, symbolic=True)],
                           ["k", "t", "x", "truth", "w", "p"], ["x_next", "y"], {} if plain else {"always_inline": True})

    def _compare(self, t, X, P, out, due):
        """The redundant gyros compared (issue 34 item 2c): ``r = ω̃₁ - ω̃₂`` on their samples,
        ``χ² = |r|²/(w₁² + w₂²)`` (w each one's white noise per sample: the difference's variance
        when the biases agree), over the gate ``persist`` samples in a row: declared; blamed the
        filter's gyro when its innovations are being rejected at the time, else the spare."""
        g1, g2 = self.pair
        m = self.mekf
        pm = P["gyro_pair"]
        w1, w2 = (g.param_layout.get(P[g.name], "white") for g in (g1, g2))
        r = out[g1.name] - out[g2.name]
        nis = ca.dot(r, r) / (w1 * w1 + w2 * w2)
        x = X["gyro_pair"]
        count = ca.if_else(due > 0.5, ca.if_else(nis > pm[0], x[0] + 1.0, 0.0), x[0])
        new = ca.logic_and(count >= pm[1], x[1] < 0.5)
        rejecting = ca.sum1(m.state.get(X["mekf"], "reject")) > 0.5
        return ca.vertcat(count, ca.fmax(x[1], new), ca.if_else(new, t, x[2]),
                          ca.if_else(new, ca.if_else(rejecting, 1.0, 2.0), x[3]))

    def spare_gyro(self):
        """The gyro the filter takes when it declares its own failed (issue 34, loop/mekf.py
        ``innovation_gate``): the first other gyro sampling at the same period, with the scene's
        innovation gate on (``[fdir] st_alpha``); None otherwise."""
        m = self.mekf
        fd = getattr(self.sensing, "fdir", None)
        if m is None or fd is None or fd.st_alpha is None:
            return None
        return next((s for s in self.sensors if s.kind == "gyro" and s is not m.gyro
                     and self.every[s.name] == self.every[m.gyro.name]), None)

    def compiled(self) -> ca.Function:
        """:meth:`function` generated as C (disk cache; casadi's evaluator without a compiler)."""
        if self._compiled is None:
            f = self.function()
            self._compiled = compile_functions([f], f.name())[f.name()]
        return self._compiled

    def record(self, x0: np.ndarray, k0: int, truth: np.ndarray, w: np.ndarray,
               params: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Ticks ``k0 .. k0 + N - 1`` in one call: states after each (N, STATE.size) and outputs
        (N, OUTPUTS.size), from the truth at each tick (N, TRUTH.size) and the noise table
        (N, NOISE.size) of :meth:`SuiteNoise.draw`."""
        truth = np.atleast_2d(np.asarray(truth, dtype=float))
        n = truth.shape[0]
        w = np.asarray(w, dtype=float).reshape(n, self.NOISE.size)
        if truth.shape[1] != TRUTH.size or np.shape(x0) != (self.STATE.size,):
            raise ValueError(f"suite record: truth {truth.shape}, expected (N, {TRUTH.size}); x0 {np.shape(x0)}, "
                             f"expected ({self.STATE.size},)")
        fc = self._records.get(n)
        if fc is None:  # a (k, n) input is the (n, k) table's numbers in order
            fc = self._records[n] = FastCall(self.compiled().mapaccum(f"suite_record_{n}", n, [2], [0]))
        ks = np.arange(k0, k0 + n, dtype=float)
        p = self.params if params is None else np.asarray(params, dtype=float)
        for arg, value in zip(fc.args, (ks, ks * self.tick, x0, truth, w, np.tile(p, n))):
            arg[:] = np.ravel(value)
        fc()
        return fc.res[0].reshape(n, -1).copy(), fc.res[1].reshape(n, -1).copy()


class SuiteNoise:
    """The noise of a suite's run seeded ``seed``, drawn tick chunk by tick chunk in order.

    Sensor i (file order) draws its rows from ``noise_rng(seed, i)``, one per sample; ``draw``
    places them on the ticks where it samples (zeros elsewhere: unused)."""

    def __init__(self, suite: Suite, seed: int):
        self.suite = suite
        self.width = suite.NOISE.size
        self.rngs = {s.name: noise_rng(seed, i) for i, s in enumerate(suite.sensors)}
        self.next_tick = 1

    def draw(self, n: int, out: np.ndarray | None = None) -> np.ndarray:
        """The noise table of the next ``n`` ticks, shape (n, NOISE.size); written into ``out``
        (that shape) when given, e.g. a compiled call's input buffer (no table in between)."""
        k0 = self.next_tick
        if out is None:
            out = np.zeros((n, self.suite.NOISE.size))
        else:  # zeros where a sensor has no sample (one sampling every tick fills its columns)
            for s in self.suite.sensors:
                if s.name in self.suite.NOISE and self.suite.every[s.name] > 1:
                    out[:, self.suite.NOISE.slice(s.name)] = 0.0
        for s in self.suite.sensors:
            if s.name not in self.suite.NOISE:
                continue
            e = self.suite.every[s.name]
            at = slice((-k0) % e, n, e)  # the ticks k0 + i with k % e == 0 (a strided view: no index array)
            out[at, self.suite.NOISE.slice(s.name)] = s.noise(self.rngs[s.name], len(range(n)[at]))
        self.next_tick += n
        return out


def _due_on(k, every: int):
    """Whether a sensor of period ``every`` ticks samples on tick ``k`` (a whole number >= 0):
    ``k > 0`` and ``every`` divides k. Every tick for ``every = 1``; else ``k == every ·
    floor(k / every)``, exact for every k below 2^52 / every (k / every is then rounded to an
    integer only when it is one), a floor and a product where ``fmod`` is a libm call per tick."""
    if every == 1:
        return k > 0.5
    return ca.logic_and(k > 0.5, k == every * ca.floor(k / every))


_DUE: dict = {}


def _due(f: ca.Function, name: str) -> ca.Function:
    """``(due, t, x, y_prev, truth, w, p) -> (x_next, y)``: the sensor's step ``f`` when due,
    else its state and last measurement held (one per sensor function, shared by its heads)."""
    hit = _DUE.get(id(f))
    if hit is not None and hit[0] is f:
        return hit[1]
    t, x, y = ca.SX.sym("t"), ca.SX.sym("x", f.size1_in(1)), ca.SX.sym("y", f.size1_out(1))
    truth, w, p = ca.SX.sym("truth", f.size1_in(2)), ca.SX.sym("w", f.size1_in(3)), ca.SX.sym("p", f.size1_in(4))
    step = ca.Function(f"{name}_do", [t, x, y, truth, w, p], f(t, x, truth, w, p))
    hold = ca.Function(f"{name}_hold", [t, x, y, truth, w, p], [x, y])
    switch = ca.Function.if_else(name, step, hold)
    _DUE[id(f)] = (f, switch)
    return switch
