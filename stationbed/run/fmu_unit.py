"""An FMI co-simulation unit (FMU) on disk, read and extracted once per process, and its
instances, reused across runs with the FMI ``reset`` (issue 23).

:func:`load_unit` reads a ``.fmu`` file's model description with FMPy, refuses what the loop
cannot fly (not an FMU, model exchange only, no binary for this platform), extracts it once to a
temporary folder and keeps it for the process (keyed by the resolved path, its size and
modification time: an FMU rebuilt between two runs is read again). :meth:`Unit.acquire` gives an
:class:`Instance` for one run: a free one, reset, or a new one instantiated; the controller
that holds it gives it back when it is garbage-collected (a Monte Carlo sample's controller, at
the next sample), so a study of any size instantiates one per process (per thread that runs
samples at the same time).

:class:`Instance` hides the differences between FMI 2 and FMI 3 (``setReal``/``setFloat64``,
``setupExperiment`` + ``enterInitializationMode``, the results of ``doStep``) and keeps the
FMU's log messages, so a failure can quote the FMU's own words.

FMPy is imported here only: a scene with an FMU law and no FMPy installed gets one line naming
the ``stationbed[fmi]`` extra.
"""

from __future__ import annotations

import atexit
import ctypes
import shutil
import tempfile
import threading
import weakref
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .controller import ControllerError, one_line

__all__ = ["FmuError", "FmuStepError", "FmiStatus", "Unit", "Instance", "load_unit", "unit_stats", "FMI_EXTRA"]

#: The optional extra that installs FMPy.
FMI_EXTRA = "stationbed[fmi]"
#: Log messages of an instance kept to quote in a failure.
LOG_KEPT = 8
#: FMI status ``fatal`` (FMI 2 and 3): no function of the instance may be called after it
FATAL = 4


class FmuError(ControllerError):
    """An FMU law that cannot be flown (set-up): one line naming the FMU and the variable."""


class FmiStatus(RuntimeError):
    """An FMI call that returned a status worse than warning (``function``, ``status``)."""

    def __init__(self, function: str, status: int):
        super().__init__(f"{function} returned status {status}")
        self.function, self.status = function, status


class FmuStepError(RuntimeError):
    """An FMU that failed during the run (``doStep`` refused, non-finite output): one line naming
    the FMU, the variable or call, and the time; the loop stops there and keeps the rows."""


def _fmpy(shown: str):
    try:
        import fmpy  # noqa: PLC0415 - optional dependency
    except ImportError:
        raise FmuError(f"controller.fmu = '{shown}' needs FMPy, which is not installed: pip install '{FMI_EXTRA}'") from None
    return fmpy


@dataclass
class Unit:
    """One FMU file of this process: its model description and extracted folder.

    Attributes
    ----------
    shown : str  The FMU as the scene names it (for messages).
    path : Path  The resolved file.
    md : fmpy ModelDescription
    version : int  2 or 3 (FMI major version).
    unzipdir : str  Where it is extracted (removed at exit).
    variables : dict  name -> fmpy ModelVariable.
    n_instantiated : int  Instances created in this process (a test and the benchmark read it).
    instances : list  Every instance of this unit not yet closed (freed in order at exit).
    """

    shown: str
    path: Path
    md: object
    version: int
    unzipdir: str
    variables: dict
    n_instantiated: int = 0
    free: list = field(default_factory=list)
    instances: list = field(default_factory=list)
    lock: threading.Lock = field(default_factory=threading.Lock)

    def acquire(self, owner) -> "Instance":
        """An instance for ``owner`` (a controller) until ``owner`` is garbage-collected: a free
        one (the caller resets it) or a new one."""
        with self.lock:
            inst = self.free.pop() if self.free else None
        if inst is None:
            inst = Instance(self)
            with self.lock:
                self.n_instantiated += 1
                self.instances.append(inst)
        # at exit :func:`_close_units` frees every instance, in order, before the folder goes
        weakref.finalize(owner, self._release, inst).atexit = False
        return inst

    def _release(self, inst: "Instance") -> None:
        if inst.broken:  # failed in its run: FMI allows little more than freeing it
            self._close(inst)
            return
        with self.lock:
            self.free.append(inst)

    def _close(self, inst: "Instance") -> None:
        with self.lock:
            if inst not in self.instances:
                return
            self.instances.remove(inst)
        inst.close()

    def close(self) -> None:
        """Free every instance (each as FMI allows after its last status), then remove the
        extracted folder: in that order, as the process exits."""
        with self.lock:
            insts, self.instances, self.free = list(self.instances), [], []
        for inst in insts:
            inst.close()
        shutil.rmtree(self.unzipdir, ignore_errors=True)


#: resolved path -> (mtime_ns, size, Unit)
_UNITS: dict[Path, tuple[int, int, Unit]] = {}
_UNITS_LOCK = threading.Lock()
#: units replaced in _UNITS by a newer version of their file (closed at exit too)
_RETIRED: list[Unit] = []
_STATS = {"extracted": 0}


def _close_units() -> None:
    """At exit (a normal end, an error, Ctrl-C or SIGTERM turned into one by the CLI): free the
    instances and remove the extracted folders of every unit, instances first."""
    with _UNITS_LOCK:
        units = [u for *_, u in _UNITS.values()] + _RETIRED
        _UNITS.clear()
        _RETIRED.clear()
    for unit in units:
        unit.close()


atexit.register(_close_units)


def unit_stats() -> dict:
    """Counts of this process: ``extracted`` (FMU files unzipped) and ``instantiated`` (FMU
    instances created, all files)."""
    units = [u for *_, u in _UNITS.values()] + _RETIRED
    return {"extracted": _STATS["extracted"], "instantiated": sum(u.n_instantiated for u in units)}


def _binary_dir(version: int, fmpy) -> str:
    return fmpy.platform if version == 2 else fmpy.platform_tuple


def load_unit(shown: str, path: Path) -> Unit:
    """The :class:`Unit` of the FMU file ``path`` (read and extracted once per file version).

    Raises
    ------
    FmuError
        One line naming the FMU: FMPy missing, no such file, not an FMU (no readable
        modelDescription.xml), not FMI 2 or 3, model exchange only, no binary for this platform.
    """
    fmpy = _fmpy(shown)
    try:
        st = path.stat()
    except OSError as e:
        raise FmuError(f"controller.fmu: no FMU {path} ({e.strerror}; '{shown}' is relative to the scene file's folder)") from None
    if not path.is_file():
        raise FmuError(f"controller.fmu: {path} is not a file")
    with _UNITS_LOCK:
        cached = _UNITS.get(path)
        if cached is not None and cached[:2] == (st.st_mtime_ns, st.st_size):
            return cached[2]
        unit = _read(fmpy, shown, path)
        if cached is not None:  # the file changed: its old folder and instances go at exit too
            _RETIRED.append(cached[2])
        _UNITS[path] = (st.st_mtime_ns, st.st_size, unit)
        return unit


def _read(fmpy, shown: str, path: Path) -> Unit:
    try:
        md = fmpy.read_model_description(str(path), validate=False)
    except Exception as e:  # a zip without modelDescription.xml, broken XML...
        raise FmuError(f"FMU '{shown}': not a readable FMU ({type(e).__name__}: {one_line(e)})") from None
    version = int(str(md.fmiVersion).split(".")[0]) if md.fmiVersion else 0
    if version not in (2, 3):
        raise FmuError(f"FMU '{shown}': FMI {md.fmiVersion} is not supported (FMI 2.0 and 3.0 co-simulation are)")
    if md.coSimulation is None:
        kinds = [k for k, v in (("model exchange", md.modelExchange), ("scheduled execution",
                                                                        getattr(md, "scheduledExecution", None))) if v]
        raise FmuError(f"FMU '{shown}' is {' and '.join(kinds) or 'no co-simulation unit'} only: stationbed flies "
                       "co-simulation FMUs (export the law for co-simulation, with a fixed-step solver)")
    ident = md.coSimulation.modelIdentifier
    plat = _binary_dir(version, fmpy)
    suffix = fmpy.sharedLibraryExtension
    import zipfile  # noqa: PLC0415

    with zipfile.ZipFile(path) as z:
        names = z.namelist()
    want = f"binaries/{plat}/{ident}{suffix}"
    if want not in names:
        have = sorted({n.split("/")[1] for n in names if n.startswith("binaries/") and n.count("/") >= 2 and not n.endswith("/")})
        has = f"it has binaries for {', '.join(have)}" if have else "it has no binaries"
        src = " (it has C sources: compile it for this platform, e.g. fmpy.util.compile_platform_binary)" \
            if any(n.startswith("sources/") for n in names) else ""
        raise FmuError(f"FMU '{shown}' has no binary for this platform: {want} is missing; {has}{src}")
    unzipdir = tempfile.mkdtemp(prefix="stationbed_fmu_")
    try:
        fmpy.extract(str(path), unzipdir)
    except Exception as e:  # a member FMPy refuses (resources/a:b.txt), a CRC error, a full disk...
        shutil.rmtree(unzipdir, ignore_errors=True)
        raise FmuError(f"FMU '{shown}': cannot extract it ({type(e).__name__}: {one_line(e)})") from None
    except BaseException:  # Ctrl-C while extracting: no folder left behind
        shutil.rmtree(unzipdir, ignore_errors=True)
        raise
    _STATS["extracted"] += 1
    variables = {v.name: v for v in md.modelVariables}
    return Unit(shown=shown, path=path, md=md, version=version, unzipdir=unzipdir, variables=variables)


# -- one instance ------------------------------------------------------------------------------

#: FMI 2 type of a variable -> the setter's name; FMI 3 types are their own names (setFloat64...)
_FMI2_SET = {"Real": "Real", "Integer": "Integer", "Enumeration": "Integer", "Boolean": "Boolean", "String": "String"}


class Instance:
    """One instantiated FMU (FMI 2 or 3 co-simulation), reused across runs.

    Use: :meth:`start` (reset if it ran before, parameters, initialisation at t = 0), then per
    tick :meth:`tick` (inputs, ``doStep``, outputs).
    """

    def __init__(self, unit: Unit):
        fmpy = _fmpy(unit.shown)
        md = unit.md
        self.unit = unit
        self.version = unit.version
        self.messages: deque[str] = deque(maxlen=LOG_KEPT)
        self.used = False
        #: the worst FMI status a call of the failed run returned (None: no error status), set
        #: by :meth:`fail`; it decides what :meth:`close` may still call
        self.failed_status: int | None = None
        self.broken = False
        kw = dict(guid=md.guid, unzipDirectory=unit.unzipdir, modelIdentifier=md.coSimulation.modelIdentifier,
                  instanceName=f"stationbed_{id(self):x}")
        try:
            if self.version == 2:
                from fmpy.fmi2 import FMU2Slave  # noqa: PLC0415

                self.slave = FMU2Slave(**kw)
                self.slave.instantiate(callbacks=self._fmi2_callbacks(fmpy), loggingOn=True)
            else:
                from fmpy.fmi3 import FMU3Slave  # noqa: PLC0415

                self.slave = FMU3Slave(**kw)
                self._log3 = self._fmi3_logger()
                self.slave.instantiate(logMessage=self._log3, loggingOn=True)
        except Exception as e:
            raise FmuError(f"FMU '{unit.shown}': cannot instantiate it ({one_line(e)}{self.said()})") from None
        # the hot calls: the C functions FMPy loaded (argument types set), without its logging
        # wrapper (~3 us a call); the status is checked in tick()
        p = "fmi2" if self.version == 2 else "fmi3"
        self._set_real = self._raw(p + ("SetReal" if self.version == 2 else "SetFloat64"))
        self._get_real = self._raw(p + ("GetReal" if self.version == 2 else "GetFloat64"))
        self._do_step = self._raw(p + "DoStep")
        if self.version == 3:
            from fmpy.fmi3 import fmi3Boolean, fmi3Float64  # noqa: PLC0415

            self._flags = [fmi3Boolean() for _ in range(3)] + [fmi3Float64()]
            self._flag_refs = [ctypes.byref(f) for f in self._flags]

    def _raw(self, name: str):
        f = getattr(self.slave, "_functions", {}).get(name)
        return f if f is not None else getattr(self.slave, name)  # another FMPy: its checked wrapper

    # -- log messages ------------------------------------------------------------------------
    def _note(self, status: int, message) -> None:
        text = message.decode("utf-8", "replace") if isinstance(message, bytes) else str(message)
        label = ["ok", "warning", "discard", "error", "fatal", "pending"][status] if 0 <= status <= 5 else str(status)
        self.messages.append(f"[{label}] {one_line(text)}")

    def _fmi2_callbacks(self, fmpy):
        from fmpy.fmi2 import (  # noqa: PLC0415
            fmi2CallbackAllocateMemoryTYPE,
            fmi2CallbackFreeMemoryTYPE,
            fmi2CallbackFunctions,
            fmi2CallbackLoggerTYPE,
        )
        from fmpy.logging import addLoggerProxy  # noqa: PLC0415

        def log(env, instance_name, status, category, message):
            self._note(status, message)

        cb = fmi2CallbackFunctions()
        cb.logger = fmi2CallbackLoggerTYPE(log)
        cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(fmpy.calloc)
        cb.freeMemory = fmi2CallbackFreeMemoryTYPE(fmpy.free)
        addLoggerProxy(ctypes.byref(cb))
        self._callbacks = cb  # kept alive as long as the instance
        return cb

    def _fmi3_logger(self):
        from fmpy.fmi3 import fmi3LogMessageCallback  # noqa: PLC0415

        def log(env, status, category, message):
            self._note(status, message)

        return fmi3LogMessageCallback(log)

    def said(self) -> str:
        """The FMU's last log messages, for a failure message (empty when it said nothing)."""
        return f"; the FMU said: {' | '.join(self.messages)}" if self.messages else ""

    # -- a run -------------------------------------------------------------------------------
    def start(self, params: list[tuple[object, object]]) -> None:
        """Reset (when it ran before), set the parameters ``[(ModelVariable, value)]``, and
        initialise at t = 0 (no stop time: the loop's last tick may step past the duration)."""
        s = self.slave
        self.messages.clear()
        if self.used:
            s.reset()
        self.used = True
        for var, value in params:
            self._set(var, value)
        if self.version == 2:
            s.setupExperiment(startTime=0.0)
            s.enterInitializationMode()
        else:
            s.enterInitializationMode(startTime=0.0)
        s.exitInitializationMode()

    def _set(self, var, value) -> None:
        vr = [var.valueReference]
        values = value if isinstance(value, list) else [value]  # an FMI 3 array: all its values
        if self.version == 2:
            getattr(self.slave, "set" + _FMI2_SET[var.type])(vr, values)
        else:
            getattr(self.slave, "set" + var.type)(vr, values)

    def bind(self, in_vrs, out_vrs, n_in_values: int | None = None, n_out_values: int | None = None) -> None:
        """Fix the value references written and read every tick (ctypes arrays, made once) and
        the numbers of values (more than references when FMI 3 arrays are among them)."""
        VR = ctypes.c_uint32
        self.n_in, self.n_out = len(in_vrs), len(out_vrs)
        self.nv_in = self.n_in if n_in_values is None else n_in_values
        self.nv_out = self.n_out if n_out_values is None else n_out_values
        self.in_vr = (VR * max(1, self.n_in))(*in_vrs)
        self.out_vr = (VR * max(1, self.n_out))(*out_vrs)
        self.inputs = np.zeros(self.nv_in) if self.nv_in else np.zeros(1)
        self.outputs = np.zeros(self.nv_out) if self.nv_out else np.zeros(1)
        dp = ctypes.POINTER(ctypes.c_double)
        self.in_ptr = self.inputs.ctypes.data_as(dp)
        self.out_ptr = self.outputs.ctypes.data_as(dp)

    def tick(self, t: float, h: float) -> None:
        """Write :attr:`inputs`, ``doStep(t, h)``, read :attr:`outputs`; :class:`FmiStatus` on
        a status worse than warning, :class:`FmuStepError` when an FMI 3 step asks to terminate
        or returns early."""
        c = self.slave.component
        if self.version == 2:
            if self.n_in:
                status = self._set_real(c, self.in_vr, self.n_in, self.in_ptr)
                if status > 1:
                    raise FmiStatus("fmi2SetReal", status)
            status = self._do_step(c, t, h, 1)
            if status > 1:
                raise FmiStatus("fmi2DoStep", status)
            if self.n_out:
                status = self._get_real(c, self.out_vr, self.n_out, self.out_ptr)
                if status > 1:
                    raise FmiStatus("fmi2GetReal", status)
            return
        if self.n_in:
            status = self._set_real(c, self.in_vr, self.n_in, self.in_ptr, self.nv_in)
            if status > 1:
                raise FmiStatus("fmi3SetFloat64", status)
        status = self._do_step(c, t, h, True, *self._flag_refs)
        if status > 1:
            raise FmiStatus("fmi3DoStep", status)
        _event, terminate, early, last = (f.value for f in self._flags)
        if terminate:
            raise FmuStepError(f"doStep({t:.6g} s, {h:.6g} s) asked to terminate the simulation{self.said()}")
        if early:
            raise FmuStepError(f"doStep({t:.6g} s, {h:.6g} s) returned early at {last:.6g} s{self.said()}")
        if self.n_out:
            status = self._get_real(c, self.out_vr, self.n_out, self.out_ptr, self.nv_out)
            if status > 1:
                raise FmiStatus("fmi3GetFloat64", status)

    def fail(self, status: int | None = None) -> None:
        """Mark the instance failed (never reused): ``status`` is the FMI status of the call that
        failed (3 error, 4 fatal), None when no call did (an output not finite, an FMI 3 step that
        asked to terminate)."""
        self.broken = True
        if status is not None:
            self.failed_status = max(status, self.failed_status or 0)

    def close(self) -> None:
        """Free the instance as FMI allows after its last status: after ``fatal`` no call at all
        (the instance and its library stay as they are until the process ends: calling
        ``fmi2Terminate`` on a Python FMU that raised crashed the process), after ``error`` only
        ``freeInstance``, else ``terminate`` (when initialised) then ``freeInstance``, which
        also unloads the library."""
        if getattr(self, "closed", False):
            return
        self.closed = True
        status = self.failed_status
        if status is not None and status >= FATAL:
            return
        if status is None and self.used:
            try:
                self.slave.terminate()
            except Exception:  # noqa: BLE001 - it is freed anyway
                pass
        try:
            self.slave.freeInstance()
        except Exception:  # noqa: BLE001
            pass
