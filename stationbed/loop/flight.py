"""What the law flies on: the truth row, the sensors and the estimate, as one function per tick.

:class:`Flight` is the sensing half of the closed loop's composition (issue 20, docs/loop.md).
Both executors run it, neither reads the other's internals:

* every executor composes :meth:`Flight.function` as ``loop/block.py``'s sensing block: the fused
  loop (``run/composed.py``) inlines it in its ``mapaccum``, the per-tick loop calls it in its
  compiled parts (``run/parts.py``; on its generic path on the measurement it is handed) (MX, so
  the suite's ``Switch`` nodes stay lazy in the generated code).

``(k, t, t_prev, y, theta_prev, omega_prev, xs, w, ps) -> (theta, xs_next, y_seen, ys)``

* ``y`` is the true measurement vector at tick k (the model's compiled ``meas``, offsets from the
  executor's measurement layout); from it the :data:`~.sensor.TRUTH` row: ``q_BN``, ``omega_BN_B``,
  ``R_N`` (``r_N``), ``sun_N``; ``moon_N`` from the station to the Moon, whose geocentric
  position is held at the scene's epoch as the Sun is (:mod:`stationbed.model.moon`; zero
  without an epoch, and the scene then refuses a Moon exclusion); ``shadow`` 1 (no shipped
  sensor reads it);
* ``theta_B = ∫ω dt`` by the trapezoid over the tick, ``theta = theta_prev + (t - t_prev)/2
  (omega_prev + omega)``: a gyro differences it, so its output is the mean of the trapezoid rates
  over its sample. The error against the exact integral is ``h³/12 |ω̈|`` per tick (ISS hold:
  ω̈ below 1e-9 rad/s³, h = 0.1 s: 1e-13 rad, against the gyro's own noise σ_v √h = 5e-7 rad);
* ``xs, w`` are the :class:`~.suite.Suite` 's state and noise row; ``ps`` its parameters then
  the Moon's geocentric position (:attr:`Flight.params`);
* ``y_seen`` is what the law receives: ``y`` with ``q_BN`` and ``omega_BN_B`` replaced by the
  MEKF's ``q_BN_hat`` and ``omega_hat_B`` when the scene has an ``[estimator]``; ``y`` itself
  otherwise (the sensors are then flown and recorded, the law keeps the ideal measurement path:
  the truth-fed comparison run);
* ``ys`` the suite's outputs (:attr:`Suite.OUTPUTS`).
"""

from __future__ import annotations

import hashlib
import pickle

import casadi as ca
import numpy as np
from scipy.stats import chi2

from ..core.compile import FastCall
from ..core.layout import Layout
from .mekf import Mekf
from .registry import build_sensors
from .sensor import TRUTH, noise_rng
from .sensor_faults import apply_sensor_faults
from .suite import Suite, SuiteNoise

__all__ = ["Flight", "INIT_STREAM", "READS", "SEEN", "flight_columns", "st_dropouts"]

#: the fields of the executor's measurement the tick reads (the truth row is made of them)
READS = ("q_BN", "omega_BN_B", "r_N", "sun_N")
#: with an estimator, the fields of the law's measurement replaced by the suite's outputs
SEEN = {"q_BN": "q_BN_hat", "omega_BN_B": "omega_hat_B"}

#: first entry of the spawn key of the initial-estimate draw (sensors use 1: SENSOR_STREAM)
INIT_STREAM = 2


def _from_offsets(offsets: dict) -> Layout:
    """The :class:`Layout` of an offset dict name -> (offset, size): its fields in offset order,
    a gap (numbers no field names) as a field ``_gap<offset>``."""
    fields, at = {}, 0
    for name, (o, n) in sorted(offsets.items(), key=lambda kv: kv[1][0]):
        if o < at:
            raise ValueError(f"measurement layout: field {name!r} at {o} overlaps the one before (ends at {at})")
        if o > at:
            fields[f"_gap{at}"] = o - at
        fields[name], at = n, o + n
    return Layout(**fields)


class Flight:
    """The sensing of a scene flown on the executor's tick.

    Parameters
    ----------
    sensing : object with ``sensor`` and ``estimator``  The scene (or a :class:`~stationbed.scene.Sensing`).
    tick : float  The controller period [s].
    layout : Layout  The executor's measurement vector (``measurement_fields``, run/measurement.py);
        an offset dict name -> (offset, size) (``Layout.offsets()``, what older code passes) is read as the same.
    seed : int  The run's seed (sensor i draws from ``noise_rng(seed, i)``).
    """

    def __init__(self, sensing, tick: float, layout: Layout | dict, seed: int, moon_R_N=None):
        self.suite = Suite(sensing, tick)
        tuned = _filter_params(sensing, tick, self.suite) if self.suite.mekf is not None else None
        #: the Moon's geocentric position [m] (N), held over the run as the Sun is (or None: no
        #: Moon, ``moon_N`` zero); the tick's parameters are the suite's, then this
        self.has_moon = moon_R_N is not None
        self.params = np.concatenate([self.suite.params, np.zeros(3) if moon_R_N is None else np.asarray(moon_R_N, float)])
        if tuned is not None:  # the filter is flight software: tuned from what it believes
            self.params[self.suite.PARAMS.slice("mekf")] = tuned
        fd = getattr(sensing, "fdir", None)
        if fd is not None and fd.st_alpha is not None and self.suite.mekf is not None:  # the innovation gate
            at = self.suite.PARAMS.slice("mekf").start
            L = self.suite.mekf.param_layout
            self.params[at + L.slice("gate").start] = float(chi2.isf(fd.st_alpha, 3))
            self.params[at + L.slice("persist").start] = float(fd.st_persistence)
        # the scene's sensor faults (issue 34): numbers of the sensors' steps (loop/sensor_faults.py)
        for name, p in apply_sensor_faults(self.suite.sensors, getattr(sensing, "fault", ())).items():
            self.params[self.suite.PARAMS.slice(name)] = p
        self.mekf = self.suite.mekf
        #: the measurement's layout (``meas``) and its offset dict (``layout``: the tick's key reads it)
        self.meas = layout if isinstance(layout, Layout) else _from_offsets(layout)
        self.layout = self.meas.offsets() if isinstance(layout, Layout) else dict(layout)
        self.ny = max(o + k for o, k in self.layout.values())
        self.seed = int(seed)
        self.heads = [s for s in self.suite.sensors if s.kind == "star_tracker"]
        m = self.mekf
        #: what the tick's expression depends on (numbers are inputs): equal keys, equal functions
        self.key = (tuple((s.name, s.key) for s in self.suite.sensors), tuple(sorted(self.suite.every.items())),
                    None if m is None else (m.gyro.name, tuple(h.name for h in m.heads), tuple(m.delays), tuple(m.every)),
                    tuple(sorted(self.layout.items())), self.has_moon,
                    None if self.suite.spare_gyro() is None else self.suite.spare_gyro().name, self.suite.pair is not None)
        self.tag = hashlib.sha256(repr(self.key).encode()).hexdigest()[:16]
        S = self.suite
        self._rows = dict(
            mekf=S.STATE.slice("mekf") if m else None,
            gyro=(S.STATE.slice(m.gyro.name), m.gyro.state.slice("bias_B")) if m else None,
            bias=S.OUTPUTS.slice("bias_B_hat") if m else None,
            valid=[S.OUTPUTS.slice(h.name).start + 4 for h in self.heads])
        self._f = self._report = self._plain = None

    @property
    def row_slices(self) -> dict:
        """Where :meth:`row` reads the suite's state and outputs (``mekf``, ``gyro``, ``bias``,
        ``valid``): the bulk rows (run/composed_rows.py) read the same."""
        return self._rows

    # -- the tick ---------------------------------------------------------------------------
    def function(self) -> ca.Function:
        """The tick as an MX function (module docstring)."""
        if self._f is not None:
            return self._f
        hit = _TICKS.get(self.key)
        if hit is not None:
            self._f = hit
            return hit
        self._f = self._tick(ca.MX, self.suite.function(), "flight_tick", _INLINE)
        _TICKS[self.key] = self._f
        return self._f

    def plain_function(self) -> ca.Function | None:
        """:meth:`function` on a plain tick (:meth:`Suite.is_plain`: the every-tick sensors
        sample, no other does) as one SX function, the suite's switches gone
        (:meth:`Suite.plain_function`); None where the suite has none."""
        if self._plain is None:
            f = self.suite.plain_function()
            self._plain = self._tick(ca.SX, f, "flight_tick_plain", {}) if f is not None else False
        return self._plain or None

    def _tick(self, cls, suite_fn: ca.Function, fname: str, opts: dict) -> ca.Function:
        """The tick's function around ``suite_fn`` in symbols of ``cls`` (MX, or SX for a plain tick)."""
        S = self.suite
        MX = cls
        k, t, t_prev = MX.sym("k"), MX.sym("t"), MX.sym("t_prev")
        y, th0, om0 = MX.sym("y", self.ny), MX.sym("theta_prev", 3), MX.sym("omega_prev", 3)
        xs, w, ps = S.STATE.symbol("xs", MX), S.NOISE.symbol("w", MX), MX.sym("ps", S.PARAMS.size + 3)

        def field(name):
            o, n = self.layout[name]
            return y[o : o + n]

        om = field("omega_BN_B")
        th = th0 + (t - t_prev) / 2 * (om0 + om)
        moon_N = MX.zeros(3)
        if self.has_moon:  # from the station: the parallax (up to 1 deg) counts in a cone's edge
            d = ps[S.PARAMS.size :] - field("r_N")
            moon_N = d / ca.norm_2(d)
        truth = TRUTH.pack(q_BN=field("q_BN"), omega_BN_B=om, theta_B=th, R_N=field("r_N"), sun_N=field("sun_N"),
                           moon_N=moon_N, shadow=MX.ones(1), symbolic=True)
        xs1, ys = suite_fn(k, t, xs, truth, w, ps[: S.PARAMS.size])
        seen = y
        if self.mekf is not None:
            parts = []
            cut = 0
            repl = {name: S.OUTPUTS.get(ys, out) for name, out in SEEN.items()}
            for name, (o, n) in sorted(self.layout.items(), key=lambda kv: kv[1][0]):
                if name in repl:
                    if o > cut:
                        parts.append(y[cut:o])
                    parts.append(repl[name])
                    cut = o + n
            if cut < self.ny:
                parts.append(y[cut:])
            seen = ca.vertcat(*parts)
        return ca.Function(fname, [k, t, t_prev, y, th0, om0, xs, w, ps], [th, xs1, seen, ys],
                           ["k", "t", "t_prev", "y", "theta_prev", "omega_prev", "xs", "w", "ps"],
                           ["theta", "xs_next", "y_seen", "ys"], opts)

    # -- the run's numbers ----------------------------------------------------------------------
    def initial(self, q_BN: np.ndarray, omega_BN_B: np.ndarray) -> np.ndarray:
        """The suite's state at tick 0. With an estimator, its attitude estimate is the truth
        turned by δα ~ N(0, σ_attitude0² E) (``q = q̂ ⊗ δq(δα)``, drawn from the run's own
        stream ``SeedSequence(seed, spawn_key=(INIT_STREAM,))``) and its bias estimate zero, so
        the initial error is what the filter's P₀ says it is. Its rate ``ω̂`` until the gyro's
        first sample is what a noise-free sample at t = 0 would give, ``ω + β₀ − β̂₀`` (the
        station flew before t = 0; zero would be a rate error of the orbital rate at the first
        ticks)."""
        if self.mekf is None:
            return self.suite.initial()
        rng = np.random.default_rng(np.random.SeedSequence(self.seed, spawn_key=(INIT_STREAM,)))
        da = self.suite.sensing.estimator.sigma_attitude0 * rng.standard_normal(3)
        dq = np.concatenate([[1.0], -da / 2])
        dq /= np.linalg.norm(dq)
        q = np.asarray(q_BN, dtype=float)
        q = q / np.linalg.norm(q)
        qh = _quat_mult(q, dq)
        x = self.suite.initial(qh if qh[0] >= 0 else -qh)
        bias0 = np.asarray(self.mekf.gyro.entry.bias0, dtype=float)
        x[self.suite.STATE.slice("omega_hat_B")] = np.asarray(omega_BN_B, dtype=float) + bias0
        return x

    def noise(self) -> "TickNoise":
        """The run's noise, tick by tick from tick 0 (:class:`TickNoise`; tick 0 draws nothing)."""
        return TickNoise(SuiteNoise(self.suite, self.seed))

    # -- columns --------------------------------------------------------------------------------
    def columns(self) -> list[str]:
        """:func:`flight_columns` of the scene."""
        return flight_columns(self.suite.sensing)

    def row(self, xs: np.ndarray, ys: np.ndarray, q_BN: np.ndarray) -> list[float]:
        """The values of :meth:`columns` from the suite's state and outputs after a tick and the
        true attitude (the true bias is the filter's gyro's state)."""
        sl = self._rows
        vals = []
        if self.mekf is not None:
            if self._report is None:
                self._report = FastCall.of(self.mekf.report_function())  # shared by the runs of a process
            r = self._report
            r.args[0][:] = xs[sl["mekf"]]
            r.args[1][:] = q_BN
            r.args[2][:] = xs[sl["gyro"][0]][sl["gyro"][1]]
            r()
            err, s3, nees = r.res[0], r.res[1], r.res[2][0]
            vals += list(np.degrees(err)) + list(np.degrees(s3[:3])) + list(ys[sl["bias"]]) + [nees]
        return vals + [float(ys[i]) for i in sl["valid"]]


def flight_columns(scene) -> list[str]:
    """The run's columns of a scene's sensing: with an estimator the attitude estimation error
    per axis (B, deg, ``q = q̂ ⊗ δq(δα)``), its 3σ (deg), the bias estimate (rad/s), ``nees``
    (6 states); per star-tracker head ``st_valid_<name>`` (1 when its held sample is valid)."""
    cols = []
    if getattr(scene, "estimator", None) is not None:
        cols += [f"est_err_{a}_deg" for a in "xyz"] + [f"est_3sigma_{a}_deg" for a in "xyz"]
        cols += [f"est_bias_{a}" for a in "xyz"] + ["nees"]
    return cols + [f"st_valid_{s.name}" for s in getattr(scene, "sensor", []) if s.kind == "star_tracker"]


def st_dropouts(valid, seen: bool = False) -> tuple[np.ndarray, bool]:
    """Which rows of a head's ``st_valid_<name>`` are dropouts: invalid after the head's first
    valid sample. Before it the head has delivered nothing yet (its first sample comes one
    period, plus its latency, after t = 0: the rows there read 0), which is not a dropout.

    Parameters
    ----------
    valid : ndarray, shape (k,)  The rows' flag (1 valid, 0 not).
    seen : bool  A valid sample came in an earlier batch of rows.

    Returns
    -------
    (mask (k,) of bool, seen after these rows)
    """
    ok = np.asarray(valid, float) >= 0.5
    since = np.logical_or.accumulate(ok) | seen if len(ok) else ok
    return ~ok & since, bool(since[-1]) if len(ok) else seen


#: the tick, the suite and the filter are inlined where they are called (an MX call copies its
#: outputs into the caller's work vector: ~90 numbers of suite state per layer and tick)
_INLINE = {"always_inline": True}
#: ticks of noise drawn at a time (any size gives the same numbers: SuiteNoise draws in tick order)
NOISE_BLOCK = 4096
_TICKS: dict = {}


class TickNoise:
    """A noise source's rows by tick, the one noise stream every executor reads: ``rows(k0, n)``
    gives ticks ``k0 .. k0+n-1``, asked in tick order (each tick once); drawn :data:`NOISE_BLOCK`
    ticks at a time. The ticks before the source's first (its ``next_tick`` at the start: the
    suite's 1, tick 0 draws nothing; the ideal measurement's corruption's 0) are zero rows. The
    rows returned are read-only to the caller (a view of the block when they lie inside it).

    The source (:class:`~.suite.SuiteNoise`, :class:`~.corruption.CorruptionNoise`) has
    ``width``, ``rngs`` (its generators by name), ``next_tick`` and ``draw(n, out=None)``: the
    rows of its next ``n`` ticks, in tick order (so any block size gives the same numbers).
    ``end``: the run's ticks (0 .. end - 1), when known: no block is drawn past them."""

    def __init__(self, noise, end: int | None = None):
        self.noise = noise
        self.width = noise.width
        self.first = noise.next_tick
        self.end = end
        self.buf, self.k0, self.next = np.zeros((0, self.width)), self.first, 0

    def _block(self, k0: int, n: int) -> int:
        """Ticks to draw from tick ``k0`` when ``n`` are needed: a block, never past the run's end."""
        m = NOISE_BLOCK if self.end is None else min(NOISE_BLOCK, self.end - k0)
        return max(m, n)

    def state(self) -> tuple:
        """Where the stream is (its block, next tick, the generators' states): :meth:`restore`
        puts it back, and the rows asked after it are drawn again, the same numbers."""
        gens = {k: r.bit_generator.state for k, r in self.noise.rngs.items()}
        return self.buf, self.k0, self.next, self.noise.next_tick, gens

    def restore(self, state: tuple) -> None:
        """Back to a :meth:`state`."""
        self.buf, self.k0, self.next, self.noise.next_tick, gens = state
        for k, g in gens.items():
            self.noise.rngs[k].bit_generator.state = g

    def rows(self, k0: int, n: int) -> np.ndarray:
        if n <= 0:
            return np.zeros((0, self.width))
        if k0 != self.next:
            raise ValueError(f"sensor noise asked for tick {k0}, the next tick is {self.next}")
        self.next = k0 + n
        i = k0 - self.k0
        if k0 >= self.first and 0 <= i and i + n <= len(self.buf):  # inside the block drawn: a view, no copy
            return self.buf[i : i + n]
        if k0 >= self.first and i == len(self.buf):  # the block used up: the next starts here (a view of it)
            self.k0, self.buf = k0, self.noise.draw(self._block(k0, n))
            return self.buf[:n]
        out = np.zeros((n, self.width))
        first = max(k0, self.first)
        while first < k0 + n:
            i = first - self.k0
            if i >= len(self.buf):
                self.k0, i = first, 0
                self.buf = self.noise.draw(self._block(first, k0 + n - first))
            m = min(len(self.buf) - i, k0 + n - first)
            out[first - k0 : first - k0 + m] = self.buf[i : i + m]
            first += m
        return out

    def rows_into(self, k0: int, n: int, out: np.ndarray) -> None:
        """:meth:`rows` written into ``out`` (shape (n, width)): drawn straight into it where the
        block drawn is used up (the same numbers: each sensor draws in tick order)."""
        first = max(k0, self.first)
        if n > 0 and k0 == self.next and first - self.k0 == len(self.buf) and first < k0 + n:
            out[: first - k0] = 0.0  # the ticks before the source's first draw nothing
            self.noise.draw(k0 + n - first, out=out[first - k0 :])
            self.next, self.k0, self.buf = k0 + n, k0 + n, np.zeros((0, self.width))
        else:
            out[...] = self.rows(k0, n)


def _quat_mult(p, q):
    pw, pv, qw, qv = p[0], p[1:], q[0], q[1:]
    return np.concatenate([[pw * qw - pv @ qv], pw * qv + qw * pv + np.cross(pv, qv)])


def _filter_params(sensing, tick: float, suite: Suite | None = None) -> np.ndarray | None:
    """The MEKF's parameters as flight software tunes them: from the sensor tables of the
    *knowledge* scene (:func:`stationbed.scene.knowledge_scene`: nominal in a Monte Carlo unless a
    dispersion is ``known``), not from the sensors being flown (``suite``: the truth's, reused
    when the knowledge changes no sensor table). None for a bare
    :class:`~stationbed.scene.Sensing` (no knowledge to apply).

    Only the knowledge's changes under ``sensor.<name>.<key>`` and ``estimator.<key>`` reach the
    filter: they are applied to the sensing tables alone (validated as a :class:`Sensing`), which
    is the knowledge scene's sensing without validating a whole scene per run; any other form of
    change to them (a whole table, an index) takes the knowledge scene itself."""
    if not hasattr(sensing, "replace"):  # a Sensing, not a Scene
        return None
    from ..scene import knowledge_scene, sensing_from_dict  # noqa: PLC0415 - the scene layer, below this one
    from ..scene.knowledge import knowledge_changes  # noqa: PLC0415

    changes = {k: v for k, v in knowledge_changes(sensing).items() if k.split(".")[0] in ("sensor", "estimator")}
    data = {"sensor": [e.model_dump(exclude_unset=True) for e in sensing.sensor],
            "estimator": sensing.estimator.model_dump(exclude_unset=True)}
    by_name = {e["name"]: e for e in data["sensor"]}
    for path, value in changes.items():
        parts = path.split(".")
        table = by_name.get(parts[1]) if parts[0] == "sensor" and len(parts) == 3 else \
            data["estimator"] if parts[0] == "estimator" and len(parts) == 2 else None
        if table is None or "[" in path:
            return _mekf_params(knowledge_scene(sensing))
        table[parts[-1]] = value
    if not changes:  # the knowledge's tables are the truth's
        return (suite or Suite(sensing, tick)).mekf.params
    key = pickle.dumps(data)  # exact (floats, arrays); a Monte Carlo's samples share their knowledge: tuned once
    hit = _TUNED.get(key)
    if hit is None:
        if len(_TUNED) >= _TUNED_MAX:
            _TUNED.clear()
        hit = _TUNED[key] = _mekf_params(sensing_from_dict(data, source="[knowledge]"))
    return hit.copy()


#: the filter's parameters by the knowledge's sensing tables (:func:`_filter_params`), at most
#: this many kept
_TUNED: dict = {}
_TUNED_MAX = 64


def _mekf_params(sensing) -> np.ndarray:
    """The parameters of the filter a sensing's tables describe (its sensors built, no suite)."""
    return Mekf.from_sensors(sensing.estimator, build_sensors(sensing.sensor)).params
