"""The sensor plug-in: its contract (:class:`Sensor`), the truth it reads (:data:`TRUTH`) and its
noise streams (:func:`noise_rng`).

A sensor is a discrete-time system stepped at its own sample period,

``(x_next, y) = step(t, x, truth, w, p)``

written **once** as casadi expressions. The same :class:`casadi.Function` is evaluated by every
executor: numerically for one sample (:meth:`Sensor.step`), over a whole record in one call
(:meth:`Sensor.record`, casadi ``mapaccum``), compiled to C (:meth:`Sensor.compiled`), or inlined
in a larger compiled loop (call :meth:`Sensor.function` on symbols). There is no numpy twin.

Randomness enters only through ``w``: ``n_noise`` standard normal numbers per sample, drawn by
the executor from the sensor's own stream (:func:`noise_rng`), so sample k of a run is the same
alone, in a batch and on any number of workers.
"""

from __future__ import annotations

from typing import ClassVar

import casadi as ca
import numpy as np

from ..core.compile import FastCall, compile_functions
from .layout import Layout

__all__ = ["Sensor", "TRUTH", "noise_rng", "SENSOR_STREAM"]

#: What an executor gives a sensor at its sample time t (the truth being flown):
#:
#: * ``q_BN`` (4): attitude of B relative to N, scalar first;
#: * ``omega_BN_B`` (3) [rad/s]: body rate at t;
#: * ``theta_B`` (3) [rad]: ∫₀ᵗ omega_BN_B dt, the running integral of the body rate (a gyro
#:   differences it between its samples: the rate integrated over the sample, exactly);
#: * ``R_N`` (3) [m]: the station's position from the Earth's centre, N components;
#: * ``sun_N``, ``moon_N`` (3): unit vectors from the station to the Sun and the Moon, N;
#: * ``shadow`` (1): the fraction of the Sun's disc seen, in [0, 1] (1 in sunlight).
TRUTH = Layout(q_BN=4, omega_BN_B=3, theta_B=3, R_N=3, sun_N=3, moon_N=3, shadow=1)

#: first entry of a sensor's spawn key (a run's other streams use other first entries)
SENSOR_STREAM = 1


def noise_rng(run_seed: int, index: int) -> np.random.Generator:
    """The noise stream of sensor ``index`` (file order) of a run seeded ``run_seed``.

    ``SeedSequence(run_seed, spawn_key=(SENSOR_STREAM, index))``: independent of the other
    sensors' streams and of the run's other draws; a Generator fills ``standard_normal((n, k))``
    row by row, so drawing a record in pieces gives the same numbers as drawing it at once.
    """
    if run_seed < 0 or index < 0:
        raise ValueError(f"seed and sensor index must be non-negative, got {run_seed}, {index}")
    return np.random.default_rng(np.random.SeedSequence(run_seed, spawn_key=(SENSOR_STREAM, index)))


class Sensor:
    """Base class of a sensor kind. One instance per ``[[sensor]]`` table of the scene.

    The public methods check and count; the plug-in writes the private ones. Rules for
    implementers:

    1. Set ``kind`` (the scene's ``[[sensor]] kind``, the registry key in
       :data:`stationbed.loop.SENSORS`) and ``scene_model`` (its pydantic table in
       :mod:`stationbed.scene.sensors`).
    2. Declare ``STATE``, ``PARAMS`` and ``OUTPUTS`` as :class:`Layout` class attributes
       (names own the indices). A kind whose *shape* depends on the table (e.g. a delay line
       as long as the latency) writes ``_layouts()`` instead and returns the shape-setting
       numbers from ``_structure()``: one compiled function per kind and structure. A switch of
       the table that leaves out a whole part of the model may be a structure too (the gyro's
       counter, only where ``quantum > 0``): a dispersion that crosses it flies two structures.
    3. Declare ``reads``, the :data:`TRUTH` fields the step uses; the step must not depend on
       any other (the contract test checks the expression).
    4. Write ``_params()``: every ``PARAMS`` field by name (numbers from the table). Numbers are
       inputs of the compiled function, never constants in it, so a dispersed value keeps the
       same compiled code.
    5. Write ``_initial()``: every ``STATE`` field at t = 0 by name.
    6. Write ``_step(t, x, truth, w, p)`` with casadi only (no numpy on symbols, no Python
       ``if`` on a symbolic value: use ``ca.if_else``). ``x``, ``truth`` and ``p`` arrive as
       dicts of fields; ``w`` is a column of ``n_noise`` standard normals, the only randomness.
       Return ``(x_next, y)`` as dicts by ``STATE`` and ``OUTPUTS`` names. The step covers
       the sample interval (t - period, t]; ``y`` is the measurement at t.
    7. A measurement that can be dropped (exclusion, saturation of a tracker) has an output
       named ``valid``: 1.0 when usable, 0.0 when not; the other outputs are then unspecified.
    8. Prove it in a test against an independent truth (closed form, geometry, or statistics:
       variance, Allan deviation, covariance inside chi-squared bands).
    """

    kind: ClassVar[str] = ""
    scene_model: ClassVar[type | None] = None
    STATE: ClassVar[Layout | None] = None
    PARAMS: ClassVar[Layout | None] = None
    OUTPUTS: ClassVar[Layout | None] = None
    reads: ClassVar[tuple[str, ...]] = ()
    n_noise: ClassVar[int] = 0

    #: the functions, by (class, key) (one per kind and shape, shared by instances)
    _functions: ClassVar[dict] = {}
    #: their mapaccum over n samples with bound buffers, by (key, n) (building one costs ~50 ms)
    _records: ClassVar[dict] = {}
    _compiled: ClassVar[dict] = {}

    def __init__(self, entry):
        if self.scene_model is not None and not isinstance(entry, self.scene_model):
            raise TypeError(f"sensor kind {self.kind!r} takes a {self.scene_model.__name__}, got {type(entry).__name__}")
        self.entry = entry
        self.name: str = entry.name
        self.period: float = float(entry.period)
        self.state, self.param_layout, self.outputs = self._layouts()
        unknown = [r for r in self.reads if r not in TRUTH]
        if unknown:
            raise ValueError(f"sensor kind {self.kind!r} reads {unknown}, not in the truth layout {TRUTH!r}")
        self.params = self.param_layout.pack(self._params())
        self.x0 = self.state.pack(self._initial())
        self.n_steps = 0

    # -- declarations -------------------------------------------------------------------
    def _layouts(self) -> tuple[Layout, Layout, Layout]:
        return self.STATE, self.PARAMS, self.OUTPUTS

    def _structure(self) -> tuple:
        return ()

    @property
    def key(self) -> str:
        """The name of this kind's compiled function for this instance's structure."""
        extra = "_".join(str(s) for s in self._structure())
        return f"sensor_{self.kind}" + (f"_{extra}" if extra else "")

    # -- the one expression ----------------------------------------------------------------
    def function(self) -> ca.Function:
        """``(t, x, truth, w, p) -> (x_next, y)`` as a casadi SX Function (built once per kind
        and structure; call it on numbers or on symbols)."""
        f = Sensor._functions.get((type(self), self.key))
        if f is None:
            t = ca.SX.sym("t")
            x, truth = self.state.symbol("x"), TRUTH.symbol("truth")
            w, p = ca.SX.sym("w", self.n_noise), self.param_layout.symbol("p")
            x_next, y = self._step(t, self.state.split(x), TRUTH.split(truth), w, self.param_layout.split(p))
            x_next, y = self.state.pack(x_next, symbolic=True), self.outputs.pack(y, symbolic=True)
            f = ca.Function(self.key, [t, x, truth, w, p], [x_next, y], ["t", "x", "truth", "w", "p"],
                            ["x_next", "y"], {"cse": True})
            Sensor._functions[(type(self), self.key)] = f
        return f

    def compiled(self) -> ca.Function:
        """The same function generated as C and compiled (cached on disk by a hash of the code;
        casadi's evaluator when no compiler is present: same numbers)."""
        f = Sensor._compiled.get((type(self), self.key))
        if f is None:
            f = Sensor._compiled[(type(self), self.key)] = compile_functions([self.function()], self.key)[self.key]
        return f

    # -- evaluating it ------------------------------------------------------------------
    def step(self, t: float, x: np.ndarray, truth: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One sample: ``(x_next, y)`` at time ``t`` [s] from the state, the truth at t
        (:data:`TRUTH` layout) and this sample's ``n_noise`` standard normals."""
        args = self._checked(x, truth, w, 1)
        x_next, y = self.function()(t, *args, self.params)
        self.n_steps += 1
        return np.asarray(x_next).ravel(), np.asarray(y).ravel()

    def record(self, t: np.ndarray, truth: np.ndarray, w: np.ndarray, x0: np.ndarray | None = None,
               params: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Samples at the times ``t`` (shape (N,)) in one call (``mapaccum`` of :meth:`compiled`).

        Parameters
        ----------
        t : ndarray, shape (N,)  Sample times [s], one period apart.
        truth : ndarray, shape (N, TRUTH.size)  The truth at each sample time.
        w : ndarray, shape (N, n_noise)  Standard normals, one row per sample.
        x0 : ndarray, optional  State before the first sample (default: the table's).
        params : ndarray, optional  Parameters (default: the table's).

        Returns
        -------
        x : ndarray, shape (N, state size)  State after each sample.
        y : ndarray, shape (N, outputs size)  Measurement of each sample.
        """
        t = np.asarray(t, dtype=float).ravel()
        n = t.size
        x0 = self.x0 if x0 is None else np.asarray(x0, dtype=float)
        truth, w = np.asarray(truth, dtype=float), np.asarray(w, dtype=float)
        self._checked(x0, truth, w, n)
        p = self.params if params is None else np.asarray(params, dtype=float)
        fc = Sensor._records.get((type(self), self.key, n))
        if fc is None:  # buffers bound once: a (k, n) input is the (n, k) table's numbers in order
            fc = Sensor._records[(type(self), self.key, n)] = FastCall(self.compiled().mapaccum(f"{self.key}_record", n, [1], [0]))
        for arg, value in zip(fc.args, (t, x0, truth, w, np.tile(p, n))):
            arg[:] = np.ravel(value)
        fc()
        self.n_steps += n
        return fc.res[0].reshape(n, -1).copy(), fc.res[1].reshape(n, -1).copy()

    def noise(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """``n`` samples' standard normals, shape (n, n_noise), from ``rng`` (see :func:`noise_rng`)."""
        return rng.standard_normal((n, self.n_noise))

    def _checked(self, x, truth, w, n: int):
        x, truth, w = np.asarray(x, dtype=float), np.asarray(truth, dtype=float), np.asarray(w, dtype=float)
        if x.shape != (self.state.size,):
            raise ValueError(f"sensor {self.name!r}: state has shape {x.shape}, expected ({self.state.size},)")
        if truth.size != n * TRUTH.size or truth.shape[-1] != TRUTH.size:
            raise ValueError(f"sensor {self.name!r}: truth has shape {truth.shape}, expected ({n}, {TRUTH.size})")
        if w.size != n * self.n_noise:
            raise ValueError(f"sensor {self.name!r}: noise has {w.size} numbers, expected {n} x {self.n_noise}")
        return x, truth.ravel() if n == 1 else truth, w.ravel() if n == 1 else w

    # -- written by the plug-in ---------------------------------------------------------------
    def _params(self) -> dict:
        raise NotImplementedError

    def _initial(self) -> dict:
        raise NotImplementedError

    def _step(self, t, x: dict, truth: dict, w, p: dict) -> tuple[dict, dict]:
        raise NotImplementedError
