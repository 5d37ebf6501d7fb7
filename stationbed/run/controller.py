"""The controller extension point (DESIGN §7): base class, measurement, plant facts, registry.

A controller runs on an integer tick clock at its own ``period``; the simulation holds each
command constant over the period (zero-order hold). Per tick it receives a
:class:`Measurement` and returns a command:

* ``command = "torque"``: a body-torque request ``tau_B`` (3,) [N m] for the CMG steering law
  (the cluster delivers it within its limits; a scene without a CMG applies it directly, as an
  ideal torquer);
* ``command = "gimbal_rates"``: gimbal rates (n_gimbals,) [rad/s], bypassing the steering law
  (the rate limit still applies, and is reported).

Rules for implementers (the scipy ``OdeSolver`` pattern):

1. Set ``name`` (registry name), ``command`` and ``Params``, a pydantic model of the
   parameters (``extra="forbid"`` is inherited from :class:`ControllerParams`: an unknown
   parameter is an error naming it).
2. Write ``_reset(plant)`` (design gains from the :class:`Plant` facts; it runs once per run)
   and ``_update(t, meas)`` returning the command as a sequence of floats.
3. Set ``self.q_ref_BN`` (4,) in ``_update`` when the law has a reference attitude: the run
   logs ``att_err_deg`` (and per axis ``att_err_x/y/z_deg``) against it.
4. ``meas`` arrays are views refreshed in place every tick: copy what you keep.
5. Or write the law once, in casadi: ``symbolic_params()`` (the law's numbers, a flat array set
   by ``_reset``) and ``symbolic(t, y, cp) -> (command, q_ref_BN)`` (casadi ``t``, ``y``: the
   measurement, its fields by :func:`measurement_fields`, e.g. ``lay.get(y, "omega_BN_B")``;
   ``cp``), and no ``_update``: every executor then evaluates it compiled (the fused loop inlined,
   per tick, :meth:`Controller.update` and the lockstep batch: stationbed/run/law_compiled.py). A
   law with both is called through ``_update`` per tick (``symbolic`` must compute the same: a
   test runs both); a law that keeps a state between ticks declares it: stationbed/run/law_state.py.

What ``_update`` may return (:func:`command_values` checks it, the same on every path of the
loop): a tuple, list or 1-D numpy array of ``n`` real numbers, finite. Anything else (a (3, 1)
array, strings, None, a dict, a generator, NaN) stops the run with a
:class:`~stationbed.run.simulation.SimulationError` naming the controller, what it returned and
the time, as an exception raised in ``_update`` does (that exception is the error's
``__cause__``, with its traceback).

Where a scene's ``controller.name`` is looked up (:func:`get_controller`):

* a registry name (``pd``): the entry points of :data:`ENTRY_POINT_GROUP`;
* ``module:Class``: ``importlib.import_module(module)``, so the module must be importable
  (installed, or on ``PYTHONPATH``);
* ``path/to/file.py:Class`` (the part before the last ``:`` ends in ``.py`` or contains a path
  separator): that file, relative to the scene file's folder (absolute paths and ``~`` work
  too), loaded with :func:`importlib.util.spec_from_file_location`; no ``PYTHONPATH`` needed.

Either way the module's top-level code runs when the scene's controller is loaded (at the start
of a run, once per process and file version): a controller file is a program, trust it as one.
"""

from __future__ import annotations

import difflib
import hashlib
import importlib
import importlib.metadata
import importlib.util
import math
import os
import struct
import sys
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import lru_cache
from types import SimpleNamespace
from pathlib import Path
from typing import Annotated, Any, ClassVar

import numpy as np

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, ValidationError

from .measurement import BatchMeasurement, Measurement, command_fields, measurement_fields, measurement_layout
from .controller_error import ControllerError, one_line
from .law_compiled import CompiledForm

__all__ = [
    "Controller",
    "ControllerParams",
    "Measurement",
    "BatchMeasurement",
    "Plant",
    "ControllerError",
    "get_controller",
    "command_values",
    "one_line",
    "controller_registry",
    "measurement_layout",
    "measurement_fields",
    "UnitQuaternion",
]

#: A quaternion typed by a person (~8 digits) is unit to ~1e-8; further off is a mistake.
QUAT_PARAM_TOL = 1e-6


def _unit_quaternion(q: list[float]) -> list[float]:
    n = math.sqrt(sum(v * v for v in q))
    if abs(n - 1.0) > QUAT_PARAM_TOL:
        raise ValueError(f"quaternion norm is {n:.9g}, not 1")
    return [v / n for v in q]


#: A scalar-first unit quaternion parameter (normalised; a norm off by > 1e-6 is an error).
UnitQuaternion = Annotated[list[float], Field(min_length=4, max_length=4), AfterValidator(_unit_quaternion)]


class ControllerParams(BaseModel):
    """Base of every controller's parameter model: unknown keys and NaN/inf are errors."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


#: attributes of a controller that stay per sample (not stacked) in :meth:`Controller.batch_of`
_PER_MEMBER = frozenset({"period", "params", "params_batch", "q_ref_BN", "n_updates", "plant", "members", "n_samples",
                         "batch_failed", "batch_stopped", "_member_meas"})


@dataclass
class Plant:
    """Facts about the plant a controller may design with, at t = 0: what flight software
    believes (the scene's knowledge, :func:`stationbed.scene.knowledge_scene`), never the truth
    being flown; ``scene`` is that knowledge scene.

    inertia_O_B : (3, 3)  Total inertia about the composite mass centre, B axes [kg m²].
    mean_motion : float or None  Orbital rate n [rad/s]; None in deep space.
    cmg_kind : str or None  "ideal", "dgcmg", "sgcmg_pyramid" or None.
    h_capacity : float  Cluster momentum capacity [N m s] (inf without a limit).
    max_torque : float  Torque limit of an ideal cluster [N m] (inf when none).
    n_gimbals : int ; max_gimbal_rate : float [rad/s] ; h_rotor : float [N m s]
    cmg_functions : dict of casadi Functions ``h``, ``A``, ``actuate`` (see cmg.cluster_functions)
    period : float  Controller period [s].
    """

    scene: Any
    inertia_O_B: np.ndarray
    mean_motion: float | None
    period: float
    cmg_kind: str | None = None
    h_capacity: float = math.inf
    max_torque: float = math.inf
    n_gimbals: int = 0
    max_gimbal_rate: float = math.inf
    h_rotor: float = 0.0
    cmg_functions: dict = field(default_factory=dict)


class Controller(CompiledForm):
    """Base class of attitude laws; see the module docstring for the contract."""

    name: ClassVar[str] = ""
    command: ClassVar[str] = "torque"
    Params: ClassVar[type[ControllerParams]] = ControllerParams
    #: parameters naming a file relative to the scene file's folder (a sample's scene written
    #: elsewhere makes them absolute)
    file_params: ClassVar[tuple[str, ...]] = ()

    def __init__(self, period: float = 0.1, **params):
        if not (period > 0 and math.isfinite(period)):
            raise ControllerError(f"controller period must be a positive number of seconds, got {period}")
        self.period = float(period)
        try:
            self.params = self.Params(**params)
        except ValidationError as e:
            err = e.errors()[0]
            where = ".".join(str(x) for x in err["loc"])
            if err["type"] == "extra_forbidden":
                valid = ", ".join(self.Params.model_fields) or "(none)"
                raise ControllerError(
                    f"controller '{self.name}': unknown parameter '{where}'; valid: {valid}"
                ) from None
            field = f"params.{where}" if where else "params"
            msg = err["msg"].removeprefix("Value error, ")
            raise ControllerError(f"controller '{self.name}': {field}: {msg}") from None
        self.q_ref_BN: np.ndarray | None = None
        self.n_updates = 0
        self.plant: Plant | None = None

    def reset(self, plant: Plant) -> None:
        """Prepare for a run (design gains); called once before the first tick."""
        self.plant = plant
        self.n_updates = 0
        self.q_ref_BN = None
        self._law = None  # the compiled symbolic form (law_compiled.py), built at its first call
        self._reset(plant)

    def check(self, plant: Plant) -> None:
        """Refuse, before a command opens any output, what only the plant shows (the command
        line calls it; nothing by default: a law's refusals come from :meth:`reset`)."""

    def update(self, t: float, meas: Measurement):
        """The command for the period starting at ``t`` [s] (counted in ``n_updates``).

        Parameters
        ----------
        t : float  Time of the tick [s].
        meas : Measurement  What the controller sees (views refreshed in place).

        Returns
        -------
        sequence of float  ``tau_B`` (3,) [N m] or gimbal rates (n_gimbals,) [rad/s], per ``command``
            (a tuple, list or 1-D array of finite floats: :func:`command_values` says what else
            the loop refuses).
        """
        self.n_updates += 1
        if self.has_symbolic():
            law = self.compiled_law()
            cmd = law(t, meas)
            law.finish()  # the state handed back after every call: summary() sees it
            return cmd
        return self._update(t, meas)

    def tick_update(self):
        """``(call, counted)``: what a per-tick executor calls every tick with ``(t, meas)``, and
        whether that call counts itself in ``n_updates``: :meth:`_update` (uncounted: the
        executor adds its calls with :meth:`count_compiled_updates` when it hands the run back,
        one Python call less per tick) unless the law overrides :meth:`update`, which is then
        called as it is. So ``n_updates`` is the run's count after the run, on every executor
        (the fused and batch loops count theirs at the end too), not a clock inside ``_update``
        (a law that needs its tick count keeps its own)."""
        if type(self).update is Controller.update:
            if self.has_symbolic():
                return self.compiled_law(), False
            return self._update, False
        return self.update, True

    def count_compiled_updates(self, n: int) -> None:
        """Count ``n`` updates that the controller's :meth:`symbolic` form made inside a compiled
        loop (the fused loop of :mod:`stationbed.run.fused`), where :meth:`update` is not called."""
        self.n_updates += int(n)

    def summary(self) -> dict:
        """Design facts to report (poles, margins...); empty by default."""
        return {}

    # -- batch (many samples per call; stationbed/run/lockstep.py) -------------------------
    @classmethod
    def batch_of(cls, members: list["Controller"]) -> "Controller":
        """One stand-in for ``members`` (each reset with its own plant) in :meth:`update_batch`:
        each number, tuple of numbers or array set in ``_reset`` becomes an array with a leading
        sample axis (a gain (n,), ``J`` (n, 3, 3)); strings and flags are the first member's (a
        differing one: the list of values); other objects the first's; ``params_batch.<name>``:
        the numeric parameters (n,); ``members``: the per-sample controllers (docs/design.md)."""
        b = object.__new__(cls)
        b.__dict__.update(members[0].__dict__)
        for name, v in members[0].__dict__.items():
            if name in _PER_MEMBER or v is None:
                continue
            vals = [getattr(m, name, None) for m in members]
            if isinstance(v, (bool, str)):  # a switch: one value for the batch, or the list of them
                if any(w != v for w in vals):
                    setattr(b, name, vals)  # (a law that assumes one value then fails, loudly)
                continue
            try:
                arr = np.asarray(vals)
            except (TypeError, ValueError):
                continue  # ragged: the first member's
            if arr.dtype.kind in "iuf" and arr.shape[0] == len(members):  # (complex poles: the first's)
                setattr(b, name, arr.astype(float))
        b.params_batch = SimpleNamespace(**{
            name: np.array([getattr(m.params, name) for m in members], dtype=float)
            for name, v in members[0].params.__dict__.items()
            if isinstance(v, (int, float)) and not isinstance(v, bool)})
        b.members = list(members)
        b.n_samples = len(members)
        b.batch_failed = {}
        b.batch_stopped = set()  # samples that failed: not called again (the executor keeps it)
        b.q_ref_BN = None
        b._law = b._batch_law = None
        return b

    def update_batch(self, t: float, meas: BatchMeasurement):
        """The commands (n_samples, n_command) of every sample for the period starting at ``t``
        [s], called on :meth:`batch_of`'s stand-in; ``meas`` fields have a leading sample axis;
        set ``self.q_ref_BN`` (n, 4) or None. A non-finite row fails that sample alone. This
        default calls each member's :meth:`update` (correct for any law, as slow as per tick); a
        member that raises or returns a bad command gets a NaN row and ``batch_failed[i] =
        (reason, exception)``; the others go on. A law with a ``symbolic`` form (and no
        ``_update`` of its own) is evaluated compiled, mapped over the samples
        (:class:`~.law_compiled.CompiledBatch`)."""
        if self.has_symbolic():
            return self._symbolic_batch(t, meas)
        per = self.__dict__.get("_member_meas")
        if per is None or per[0] is not meas.y:  # each member's Measurement (a row of meas.y), its update
            per = self._member_meas = (meas.y, [(m.update, m, Measurement(meas.y[i], meas.layout))
                                                for i, m in enumerate(self.members)])
        ncmd = command_fields(self.command, self.members[0].plant.n_gimbals).size
        out = np.full((meas.n_samples, ncmd), np.nan)
        self.batch_failed = {}
        pack, step = _doubles(ncmd).pack_into, 8 * ncmd
        stopped = self.batch_stopped
        for i, (update, m, mi) in enumerate(per[1]):
            if stopped and i in stopped:
                continue
            mi.t = t
            try:
                cmd = update(t, mi)
            except Exception as e:  # the user's code: this sample fails, the batch goes on
                self.batch_failed[i] = (f"controller '{m.name}' raised {type(e).__name__}: {one_line(e)}", e)
                continue
            cls = cmd.__class__
            try:  # as the per-tick loop writes a command: n real numbers, else the checker says why
                if cls is tuple or cls is list:
                    pack(out, i * step, *cmd)
                elif cls is np.ndarray and cmd.dtype == np.float64 and cmd.shape == (ncmd,):
                    out[i] = cmd
                else:
                    raise TypeError
            except (TypeError, ValueError, struct.error):
                try:
                    out[i] = command_values(cmd, ncmd, m.command)
                except ValueError as e:
                    out[i] = np.nan
                    self.batch_failed[i] = (f"controller '{m.name}' returned {e}", None)
        return self._failed_rows(out)

    def _failed_rows(self, out: np.ndarray) -> np.ndarray:
        """``out``, each non-finite row of a sample not stopped given the checker's reason."""
        if math.isfinite(out.sum()):  # every row finite (a NaN or inf anywhere makes the sum one)
            return out
        stopped = self.batch_stopped
        bad = ~np.isfinite(out).all(axis=1)
        if bad.any():  # NaN or inf written as numbers: the checker's reason (the values are the same)
            for i in np.flatnonzero(bad):
                if i not in stopped and i not in self.batch_failed:
                    try:
                        command_values(out[i], out.shape[1], self.members[i].command)
                    except ValueError as e:
                        self.batch_failed[i] = (f"controller '{self.members[i].name}' returned {e}", None)
        return out

    # -- plug-in -------------------------------------------------------------------------
    def _reset(self, plant: Plant) -> None:
        pass

    def _update(self, t: float, meas: Measurement):  # pragma: no cover - abstract
        raise NotImplementedError

    _update.abstract = True  # (CompiledForm.has_symbolic: a law that writes no _update)


#: The longest quotation of a bad command in an error message [characters].
SHOWN_CHARS = 80


def _shown(obj) -> str:
    """A one-line, bounded ``repr`` of what a controller returned (never raises)."""
    try:
        text = " ".join(repr(obj).split())
    except Exception:  # a user's object with a broken __repr__
        text = f"<{type(obj).__name__}>"
    return text if len(text) <= SHOWN_CHARS else text[: SHOWN_CHARS - 3] + "..."


def _what(obj) -> str:
    """What a controller returned, for a message: ``None``, or the value and its type."""
    return "None" if obj is None else f"{_shown(obj)} ({type(obj).__name__})"


def _real(c) -> float | None:
    """``c`` as a float when it is one real number (Python or numpy), else None."""
    if isinstance(c, (str, bytes, bytearray, complex, np.complexfloating)):
        return None
    if isinstance(c, np.ndarray) and c.ndim > 0:
        return None
    try:
        return float(c)
    except (TypeError, ValueError, OverflowError):
        return None


@lru_cache(maxsize=None)
def _doubles(n: int) -> struct.Struct:
    """``n`` native doubles: packing one refuses anything but real numbers (strings, None...)."""
    return struct.Struct(f"={n}d")


def command_values(value, n: int, kind: str = "torque", finite: bool = True) -> np.ndarray:
    """What a controller returned (or set as ``q_ref_BN``), checked: ``n`` finite floats.

    The one definition of a valid command, used on every path of the loop (the per-tick fast
    path writes plain tuples, lists and float64 arrays itself and asks this function about
    anything else).

    Parameters
    ----------
    value : object  What ``Controller.update`` returned.
    n : int  Values expected: 3 for a torque [N m], ``n_gimbals`` for gimbal rates [rad/s].
    kind : str  What the value is, for the message: the controller's ``command``
        ("torque" or "gimbal_rates"), or "q_ref_BN".
    finite : bool  Refuse NaN and inf (False for ``q_ref_BN``: a NaN reference only logs a NaN
        ``att_err_deg``).

    Returns
    -------
    ndarray, shape (n,)  The values as float64.

    Raises
    ------
    ValueError
        One line, to follow "returned" (or "set q_ref_BN to"): what came back and what was
        expected. Refused: anything not a sequence (None, a number, a string, a dict, a set, a
        generator...), the wrong length or shape (a (3, 1) array), an element that is not a
        real number (a string, None, a complex number), NaN or inf (when ``finite``). A tuple, list or 1-D numpy
        array of Python or numpy ints and floats is accepted.
    """
    cls = value.__class__
    if (cls is tuple or cls is list) and len(value) == n:  # the usual case, quickly
        try:
            values = _doubles(n).unpack(_doubles(n).pack(*value))  # numbers only: no strings, None
        except struct.error:
            pass  # the checks below say what is wrong
        else:
            if not finite or all(map(math.isfinite, values)):
                return np.array(values)
    elif cls is np.ndarray and value.dtype == np.float64 and value.shape == (n,):
        if not finite or np.isfinite(value).all():
            return value.copy()
    expected = f"{n} real numbers ({kind})"
    if isinstance(value, np.ndarray):
        if value.shape != (n,):
            raise ValueError(f"a numpy array of shape {value.shape}, expected shape ({n},): {expected}")
        if value.dtype.kind not in "biufO":
            raise ValueError(f"a numpy array of dtype {value.dtype}, expected {expected}")
        items = value.tolist()
    elif value is None or isinstance(value, (str, bytes, bytearray, Mapping, set, frozenset)):
        raise ValueError(f"{_what(value)}, not a sequence of {expected}")
    else:
        try:
            size = len(value)
            items = list(value)
        except Exception:  # no len() (a number, a generator, ...) or a sequence that fails
            raise ValueError(f"{_what(value)}, not a sequence of {expected}") from None
        if size != n or len(items) != n:
            raise ValueError(f"{size} values, expected {expected}")
    values = [_real(c) for c in items]
    for i, v in enumerate(values):
        if v is None:
            raise ValueError(f"{_shown(value)}: element {i} is {_what(items[i])}, not a real number; expected {expected}")
    if finite and not all(math.isfinite(v) for v in values):
        raise ValueError(f"non-finite values {values} ({kind})")
    return np.array(values)


#: Entry-point group of controllers: the shipped laws (pyproject.toml) and any installed package's.
ENTRY_POINT_GROUP = "stationbed.controllers"


_ENTRY_POINTS: dict = {}


def _entry_points():
    """The group's entry points, scanned once per ``sys.path`` (the scan reads every installed
    distribution's metadata: ~5 ms, once per Monte Carlo sample before; issue 25)."""
    key = tuple(sys.path)
    if key not in _ENTRY_POINTS:
        _ENTRY_POINTS.clear()
        _ENTRY_POINTS[key] = {ep.name: ep for ep in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP)}
    return _ENTRY_POINTS[key]


def _load(ep) -> type[Controller]:
    cls = ep.load()
    if not (isinstance(cls, type) and issubclass(cls, Controller)):
        raise ControllerError(f"controller entry point '{ep.name}' ({ep.value}) is not a Controller subclass")
    return cls


def controller_registry() -> dict[str, type[Controller]]:
    """Every registered controller by scene name (entry points of :data:`ENTRY_POINT_GROUP`)."""
    return {name: _load(ep) for name, ep in sorted(_entry_points().items())}


def _is_file_name(module: str) -> bool:
    """Whether the module part of ``module:Class`` names a file (``.py``, or a path)."""
    return module.endswith(".py") or any(sep in module for sep in ("/", os.sep, os.altsep) if sep)


#: Controller files loaded in this process: resolved path -> (mtime_ns, size, module).
_FILE_MODULES: dict[Path, tuple[int, int, Any]] = {}


def _load_file(name: str, file: str, base_dir: str | Path | None):
    """The module of a controller file (loaded once per file version); ControllerError naming it."""
    path = Path(file).expanduser()
    if not path.is_absolute():
        path = Path(base_dir if base_dir is not None else ".") / path
    path = path.resolve()
    try:
        st = path.stat()
    except FileNotFoundError:
        where = "the scene file's folder" if base_dir is not None else "the current folder"
        raise ControllerError(f"controller '{name}': no file {path} ({file} is relative to {where})") from None
    except OSError as e:
        raise ControllerError(f"controller '{name}': cannot read {path} ({e.strerror})") from None
    if not path.is_file():
        raise ControllerError(f"controller '{name}': {path} is not a file")
    cached = _FILE_MODULES.get(path)
    if cached is not None and cached[:2] == (st.st_mtime_ns, st.st_size):
        return cached[2]
    # a unique module name per file, stable across loads (classes pickle, dataclasses work)
    digest = hashlib.sha256(str(path).encode()).hexdigest()[:12]
    stem = "".join(ch if ch.isalnum() else "_" for ch in path.stem)
    mod_name = f"stationbed_controller_file_{stem}_{digest}"
    spec = importlib.util.spec_from_file_location(mod_name, path)
    if spec is None or spec.loader is None:
        raise ControllerError(f"controller '{name}': {path} is not a Python file")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[mod_name] = mod
    try:
        spec.loader.exec_module(mod)  # the file's top-level code runs here
    except SyntaxError as e:
        del sys.modules[mod_name]
        raise ControllerError(f"controller '{name}': {path}:{e.lineno}: syntax error ({e.msg})") from e
    except Exception as e:
        del sys.modules[mod_name]
        raise ControllerError(f"controller '{name}': loading {path} raised {type(e).__name__}: {one_line(e)}") from e
    _FILE_MODULES[path] = (st.st_mtime_ns, st.st_size, mod)
    return mod


def get_controller(name: str, base_dir: str | Path | None = None) -> type[Controller]:
    """A controller class from a registry name, ``module:Class`` or ``path/file.py:Class``.

    Parameters
    ----------
    name : str
        The scene's ``controller.name``. The part before the last ``:`` is a file when it ends
        in ``.py`` or contains a path separator, else a module name.
    base_dir : str or Path, optional
        The folder a relative controller file is found in: the scene file's folder
        (``Scene.folder``); the current folder when None.

    Raises
    ------
    ControllerError
        One line naming the controller (and the file): unknown name, module that cannot be
        imported, missing file, syntax error or exception while loading it, no such class, not
        a :class:`Controller` subclass.
    """
    if ":" in name:
        mod_name, _, cls_name = name.rpartition(":")
        if _is_file_name(mod_name):
            mod = _load_file(name, mod_name, base_dir)
            where = str(Path(mod.__file__))
        else:
            try:
                mod = importlib.import_module(mod_name)
            except ImportError as e:
                hint = ""
                near = Path(base_dir if base_dir is not None else ".") / (mod_name.replace(".", "/") + ".py")
                if near.is_file():
                    hint = f"; to load {near} without PYTHONPATH, name it '{mod_name.replace('.', '/')}.py:{cls_name}'"
                raise ControllerError(f"controller '{name}': cannot import module '{mod_name}' ({e}){hint}") from None
            except Exception as e:  # the module's top-level code raised, or has a syntax error
                raise ControllerError(
                    f"controller '{name}': importing module '{mod_name}' raised {type(e).__name__}: {one_line(e)}"
                ) from e
            where = f"'{mod_name}'"
        cls = getattr(mod, cls_name, None)
        if cls is None:
            laws = [k for k, v in vars(mod).items() if isinstance(v, type) and issubclass(v, Controller)
                    and v is not Controller]
            raise ControllerError(f"controller '{name}': no class '{cls_name}' in {where}{_nearest(cls_name, laws)}")
        if not (isinstance(cls, type) and issubclass(cls, Controller)):
            raise ControllerError(f"controller '{name}': '{cls_name}' is not a Controller subclass in {where}")
        return cls
    eps = _entry_points()
    if name not in eps:
        hint = f"; to load a file, name its class: '{name}:ClassName'" if _is_file_name(name) else ""
        raise ControllerError(
            f"unknown controller '{name}'; valid: {', '.join(sorted(eps))}, module:Class or path/file.py:Class{hint}"
            f"{_nearest(name, list(eps))}"
        )
    return _load(eps[name])


def _nearest(name: str, names: list[str]) -> str:
    """``; did you mean '<nearest>'?`` for a misspelt law name among ``names`` (else "")."""
    close = difflib.get_close_matches(name, names, n=1, cutoff=0.6)
    return f"; did you mean '{close[0]}'?" if close else ""
