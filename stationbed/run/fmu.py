"""An FMI co-simulation unit (FMU) as the loop's attitude law (issue 23).

``[controller] fmu = "laws/hold.fmu"`` (relative to the scene file's folder) flies a law exported
from Simulink, Modelica or any FMI tool. :class:`FmuController` is a :class:`Controller` like a
Python law: the loop calls it every tick, holds its command over the period, and stops with the
rows kept when it fails.

The contract (docs/design.md, "FMU laws"):

* **Variables by name.** The loop's names are the measurement's elements, ``q_BN[0..3]``,
  ``omega_BN_B[0..2]``, ``h_B[0..2]``, ``gimbal[..]``, ``alpha[..]``, ``beta[..]``, ``r_N[0..2]``,
  ``C_ON[0..8]`` (row-major), ``q_ON[0..3]``, ``omega_ON_O[0..2]``, ``sun_N[0..2]``
  (:class:`~.controller.Measurement`), and the outputs ``tau_cmd[0..2]`` (a body torque request
  [N m]) or ``gimbal_rate_cmd[0..n-1]`` (gimbal rates [rad/s]), and optionally
  ``q_ref_BN[0..3]`` (the reference the run logs ``att_err_deg`` against). An FMU variable of
  the same name is connected by convention; ``[controller.variables]`` maps the others, an
  element (``"q_BN[0]" = "qw"``) or a whole field (``q_BN = "q"``: ``q[0..3]`` or, 1-based as
  Modelica and MATLAB number them, ``q[1..4]``). Every FMU input must be driven; the command
  outputs must exist. The command kind follows from the outputs the FMU has.
* **Parameters** from ``[controller.params]``, by FMU variable name (a list sets ``name[0..]``
  or ``name[1..]``); FMU parameters named ``inertia_O_B[0..8]`` (row-major, kg m²),
  ``mean_motion`` (rad/s; 0 in deep space) and ``period`` (s) are set from the plant facts when
  the scene does not give them.
* **Timing.** At the tick at ``t`` the loop writes the inputs (the measurement at ``t``), calls
  ``doStep(t, period)`` and reads the outputs: the command held over ``[t, t + period)``, as a
  Python law's. The FMU is initialised at t = 0 with no stop time; the communication step is the
  controller period.
* **Failures** are one line naming the FMU and the variable (set-up: :class:`FmuError`, exit 2)
  or the time (``doStep`` refused, non-finite output: :class:`FmuStepError`, the rows up to then
  kept).
"""

from __future__ import annotations

import difflib
import math
import re
from operator import itemgetter
from pathlib import Path

import numpy as np

from ..core import interrupts
from .controller import Controller, one_line
from .measurement import measurement_fields
from .fmu_unit import FmuError, FmuStepError, load_unit

__all__ = ["FmuController", "FmuError", "FmuStepError", "COMMAND_OUTPUTS"]

#: command kind -> the output field that carries it
COMMAND_OUTPUTS = {"torque": "tau_cmd", "gimbal_rates": "gimbal_rate_cmd"}
#: the optional output of the reference attitude (scalar first)
Q_REF = "q_ref_BN"
#: FMU parameters set from the plant facts when the scene does not give them: name -> size
PLANT_PARAMS = {"inertia_O_B": 9, "mean_motion": 1, "period": 1}
#: the measurement's fields (sizes of gimbal, alpha, beta: per scene)
MEASUREMENT_FIELDS = measurement_fields(0, 0).names
_ELEMENT = re.compile(r"^(.*)\[(\d+)\]$")
#: how many near names an error lists
NEAR = 4
#: a tick (k * period, computed) is on the FMU's clock (a sum of steps) within this, relative to t
CLOCK_RTOL = 1e-9


def _split(name: str) -> tuple[str, int | None]:
    m = _ELEMENT.match(name)
    return (m.group(1), int(m.group(2))) if m else (name, None)


def _closest(name: str, names) -> list[str]:
    """Up to :data:`NEAR` of ``names`` most like ``name`` (difflib's ratio; ties in name order)."""
    scored = []
    for n in set(names):
        m = difflib.SequenceMatcher(None, name, n)
        if m.real_quick_ratio() >= 0.3 and m.quick_ratio() >= 0.3 and (r := m.ratio()) >= 0.3:
            scored.append((-r, n))
    return [n for _, n in sorted(scored)[:NEAR]]


def _near(name: str, names) -> str:
    close = _closest(name, names)
    return f"; nearest: {', '.join(repr(c) for c in close)}" if close else "; it has none of that kind"


def _is_float(var) -> bool:
    return var.type in ("Real", "Float64")


class FmuController(Controller):
    """A co-simulation FMU flown as the attitude law (see the module docstring for the contract).

    Parameters
    ----------
    fmu : str  The FMU file as the scene names it (relative to ``base_dir``).
    period : float  Controller period = communication step [s].
    params : dict  FMU parameters by name (``[controller.params]``).
    variables : dict  Loop name -> FMU variable (``[controller.variables]``).
    base_dir : path, optional  The scene file's folder (the current folder when None).
    """

    name = "fmu"

    def __init__(self, fmu: str, *, period: float = 0.1, params: dict | None = None,
                 variables: dict | None = None, base_dir=None):
        super().__init__(period)
        self.name = fmu  # messages name the FMU as the scene does
        path = Path(fmu).expanduser()
        if not path.is_absolute():
            path = Path(base_dir if base_dir is not None else ".") / path
        self.unit = load_unit(fmu, path.resolve())
        self.fmu_params = dict(params or {})
        self.variables = dict(variables or {})
        self._vars = self.unit.variables
        self._check_keys()
        self._param_values = self._params(self.fmu_params)
        self.command = self._command_kind()
        self._inst = None

    # -- names -------------------------------------------------------------------------------
    def _err(self, where: str, what: str) -> FmuError:
        return FmuError(f"{where}: FMU '{self.name}' {what}")

    def _of(self, causality: str) -> list[str]:
        return [n for n, v in self._vars.items() if v.causality == causality]

    def _check_keys(self) -> None:
        known = MEASUREMENT_FIELDS + tuple(COMMAND_OUTPUTS.values()) + (Q_REF,)
        for key, value in self.variables.items():
            field, _ = _split(key)
            if field not in known:
                close = _closest(field, known)
                hint = f"nearest: {', '.join(close)}" if close else f"the loop's names: {', '.join(known)}"
                raise FmuError(f"controller.variables.{key}: '{key}' is not a loop name; {hint}")
            causality = "output" if field in COMMAND_OUTPUTS.values() or field == Q_REF else "input"
            if _split(key)[1] is not None:
                self._check_var(f"controller.variables.{key}", value, causality)

    def _size(self, name: str) -> int:
        """Values a variable holds: 1 for a scalar, the product of its dimensions for an FMI 3 array."""
        dims = getattr(self._vars[name], "dimensions", None) or []
        n = 1
        for d in dims:
            start = getattr(d, "start", None)
            if start in (None, ""):
                raise self._err("controller.fmu", f"array '{name}' has a dimension set by a structural parameter: "
                                "stationbed exchanges arrays of fixed size only")
            n *= int(start)
        return n

    def _check_var(self, where: str, name: str, causality: str, size: int | None = 1) -> None:
        """``name`` is an FMU variable of ``causality`` holding Real/Float64 values, ``size`` of
        them (a scalar for 1; any size for None)."""
        var = self._vars.get(name)
        if var is None:
            raise self._err(where, f"has no variable '{name}'{_near(name, self._of(causality))}")
        if var.causality != causality:
            role = "a measurement drives an FMU input" if causality == "input" else "the command is an FMU output"
            raise self._err(where, f"variable '{name}' is {_a(var.causality)}, not {_a(causality)} ({role})")
        if not _is_float(var):
            raise self._err(where, f"variable '{name}' is {var.type}: the loop exchanges Real (FMI 2) / Float64 (FMI 3) values")
        n = self._size(name)
        if size is not None and n != size:
            what = f"an array of {n} values" if n > 1 else "a scalar"
            raise self._err(where, f"variable '{name}' is {what}, expected {size}" + (
                ": map the whole field to an array (field = \"name\")" if size == 1 else ""))

    def _expand(self, where: str, base: str, n: int) -> list[tuple[str, int]]:
        """The slots ``(variable, element)`` of a field of ``n`` values: an FMI 3 array ``base``
        of ``n`` values, or the scalars ``base[0..n-1]`` or ``base[1..n]``, whichever the FMU has."""
        if base in self._vars and getattr(self._vars[base], "dimensions", None) and self._size(base) == n:
            return [(base, j) for j in range(n)]
        for b in (0, 1):
            names = [f"{base}[{b + i}]" for i in range(n)]
            if all(x in self._vars for x in names):
                return [(x, 0) for x in names]
        raise self._err(where, f"has no variables {base}[0..{n - 1}] or {base}[1..{n}] (nor an array '{base}' of {n})"
                        f"{_near(base + '[0]', self._vars)}")

    def _element_map(self, sizes: dict[str, int]) -> dict[str, tuple[str, int]]:
        """Loop element -> FMU slot ``(variable, element)``, from ``[controller.variables]``."""
        out = {}
        for key, value in self.variables.items():
            field, i = _split(key)
            where = f"controller.variables.{key}"
            n = sizes[field]
            if i is None:
                causality = "input" if field in MEASUREMENT_FIELDS else "output"
                for j, slot in enumerate(self._expand(where, value, n)):
                    self._check_var(where, slot[0], causality, size=None)
                    out[f"{field}[{j}]"] = slot
            elif i >= n:
                raise FmuError(f"{where}: the scene's {field} has {n} elements ({field}[0..{n - 1}])" if n else
                               f"{where}: the scene has no {field} (no such element)")
            else:
                out[key] = (value, 0)
        return out

    def _conventional(self, field: str, n: int) -> list[tuple[str, int]] | None:
        """The slots of ``field`` by the loop's own name (scalars ``field[i]`` or an array ``field``)."""
        if field in self._vars and getattr(self._vars[field], "dimensions", None) and self._size(field) == n:
            return [(field, j) for j in range(n)]
        return None

    def _shown(self, slot: tuple[str, int]) -> str:
        name, j = slot
        return f"{name}[{j}] (array element)" if self._size(name) > 1 else name

    def _command_kind(self) -> str:
        """"torque" or "gimbal_rates": which command outputs the FMU has (by convention or map)."""
        outputs = set(self._of("output"))
        mapped = {_split(k)[0] for k in self.variables}
        found = [kind for kind, f in COMMAND_OUTPUTS.items() if f in mapped]  # a map decides
        if not found:  # else the outputs' names
            found = [kind for kind, f in COMMAND_OUTPUTS.items() if any(_split(o)[0] == f for o in outputs)]
        if len(found) == 1:
            return found[0]
        if found:
            raise self._err("controller.variables", "has both tau_cmd and gimbal_rate_cmd outputs: the loop "
                            "takes one command; map the one to fly in [controller.variables]")
        raise self._err("controller.fmu", "has no command output: name its outputs tau_cmd[0..2] (torque, N m) "
                        "or gimbal_rate_cmd[0..] (rad/s), or map them in [controller.variables]"
                        f"{_near('tau_cmd[0]', outputs)}")

    # -- parameters --------------------------------------------------------------------------
    def _params(self, params: dict) -> list:
        out = []
        for name, value in params.items():
            where = f"controller.params.{name}"
            if isinstance(value, list) and name in self._vars and getattr(self._vars[name], "dimensions", None):
                out.append(self._param(where, name, value))  # an FMI 3 array parameter
            elif isinstance(value, list):
                for (vname, _), v in zip(self._expand(where, name, len(value)), value):
                    out.append(self._param(where, vname, v))
            else:
                out.append(self._param(where, name, value))
        return out

    def _param(self, where: str, name: str, value):
        var = self._vars.get(name)
        if var is None:
            raise self._err(where, f"has no parameter '{name}'{_near(name, self._of('parameter'))}")
        if var.causality != "parameter":
            hint = ": the loop drives it (map a measurement to it in [controller.variables])" if var.causality == "input" else ""
            raise self._err(where, f"variable '{name}' is {_a(var.causality)}, not a parameter{hint}")
        if var.variability not in ("fixed", "tunable"):
            raise self._err(where, f"parameter '{name}' is {var.variability}: only fixed and tunable parameters can be set")
        if getattr(var, "dimensions", None):
            n = self._size(name)
            if not isinstance(value, list) or len(value) != n:
                raise self._err(where, f"parameter '{name}' is an array of {n} values, got {value!r}")
            return var, [_typed(self, where, var, v) for v in value]
        return var, _typed(self, where, var, value)

    def _plant_params(self, plant) -> list:
        """Parameters set from the plant facts (:data:`PLANT_PARAMS`) the scene did not give."""
        facts = {
            "inertia_O_B": [float(v) for v in np.asarray(plant.inertia_O_B).ravel()],
            "mean_motion": [float(plant.mean_motion or 0.0)],
            "period": [float(self.period)],
        }
        out = []
        for name, n in PLANT_PARAMS.items():
            if name in self.fmu_params:
                continue
            where = f"plant fact {name}"
            if name in self._vars and self._vars[name].causality == "parameter":
                if getattr(self._vars[name], "dimensions", None):  # an FMI 3 array
                    out.append(self._param(where, name, facts[name]))
                elif n == 1:
                    out.append(self._param(where, name, facts[name][0]))
                continue
            try:
                slots = self._expand("", name, n)
            except FmuError:
                continue  # the FMU does not take this fact
            for (vname, _), v in zip(slots, facts[name]):
                if self._vars[vname].causality == "parameter":
                    out.append(self._param(where, vname, v))
        return out

    # -- a run -------------------------------------------------------------------------------
    def _bind(self, plant) -> None:
        ng, na = plant.n_gimbals, len(plant.scene.appendage) if plant.scene is not None else 0
        layout = measurement_fields(ng, na).offsets()  # name -> (offset, size), by the one declaration
        sizes = {f: k for f, (o, k) in layout.items()}
        sizes.update(tau_cmd=3, gimbal_rate_cmd=ng, q_ref_BN=4)
        emap = self._element_map(sizes)
        elements = {f"{f}[{i}]": o + i for f, (o, k) in layout.items() for i in range(k)}
        # inputs: each value of each FMU input driven by exactly one measurement element
        driver: dict[tuple[str, int], str] = {}
        for el, slot in emap.items():
            if _split(el)[0] in MEASUREMENT_FIELDS:
                if slot in driver:
                    raise self._err(f"controller.variables.{el}", f"input '{self._shown(slot)}' is driven twice "
                                    f"({driver[slot]} and {el})")
                driver[slot] = el
        for f, (o, k) in layout.items():  # by the loop's names: an array `f`, or scalars `f[i]`
            slots = self._conventional(f, k) or [(f"{f}[{i}]", 0) for i in range(k)]
            for i, slot in enumerate(slots):
                el = f"{f}[{i}]"
                if el not in emap and slot not in driver and slot[0] in self._vars and self._vars[slot[0]].causality == "input":
                    driver[slot] = el
        inputs = self._of("input")
        in_idx = []
        for name in inputs:
            n = self._size(name)
            for j in range(n):
                if (name, j) not in driver:
                    shown = self._shown((name, j))
                    raise self._err("controller.variables", f"input '{shown}' is driven by no measurement: name one in "
                                    f"[controller.variables], e.g. \"q_BN[0]\" = \"{name}\"{_near(name, elements)}")
                in_idx.append(elements[driver[(name, j)]])
            self._check_var(f"controller.variables.{driver[(name, 0)]}", name, "input", size=None)
        self._in_idx = np.array(in_idx, dtype=np.intp)
        # outputs: the command, then the reference attitude when the FMU gives it
        field = COMMAND_OUTPUTS[self.command]
        conv = self._conventional(field, sizes[field]) or [(f"{field}[{i}]", 0) for i in range(sizes[field])]
        cmd = [emap.get(f"{field}[{i}]", conv[i]) for i in range(sizes[field])]
        for i, (name, j) in enumerate(cmd):
            self._check_var(f"controller.variables.{field}[{i}]", name, "output", size=None)
        conv = self._conventional(Q_REF, 4) or [(f"{Q_REF}[{i}]", 0) for i in range(4)]
        q_slots = [emap.get(f"{Q_REF}[{i}]", conv[i]) for i in range(4)]
        given = [n in self._vars and self._vars[n].causality == "output" for n, _ in q_slots]
        explicit = any(_split(k)[0] == Q_REF for k in self.variables)
        if explicit or any(given):
            for i, (name, j) in enumerate(q_slots):
                self._check_var(f"controller.variables.{Q_REF}[{i}]", name, "output", size=None)
        else:
            q_slots = []
        # the output variables read each tick (each once, in first-use order) and where each
        # slot's value lands in the values read
        out_vars, offset = [], {}
        for name, _ in cmd + q_slots:
            if name not in offset:
                offset[name] = sum(self._size(v) for v in out_vars)
                out_vars.append(name)
        pos = [offset[n] + j for n, j in cmd + q_slots]
        self._out_names = {p: self._shown(sl) for p, sl in zip(pos, cmd + q_slots)}
        self._cmd_of = itemgetter(*pos[: len(cmd)])
        self._q_of = itemgetter(*pos[len(cmd):]) if q_slots else None
        self._n_cmd = len(cmd)
        vr = lambda names: [self._vars[n].valueReference for n in names]  # noqa: E731
        self._in_vrs, self._out_vrs = vr(inputs), vr(out_vars)
        self._n_values = (len(in_idx), sum(self._size(v) for v in out_vars))

    def check(self, plant) -> None:
        """Everything a run's first tick would find, before the command line opens an output:
        the variables bound, the binary loaded and instantiated, the parameters and the
        initialisation accepted (the instance is reused by the run, reset)."""
        self._reset(plant)

    def _reset(self, plant) -> None:
        self._bind(plant)
        params = self._plant_params(plant) + self._param_values
        inst = self._inst
        if inst is None or inst.broken:
            inst = self._inst = self.unit.acquire(self)
        try:
            inst.start(params)
        except Exception as e:  # noqa: BLE001 - the FMU refused its parameters or its initialisation
            inst.fail(getattr(e, "status", None))
            raise FmuError(f"FMU '{self.name}': initialisation at t = 0 failed ({one_line(e)}{inst.said()})") from None
        inst.bind(self._in_vrs, self._out_vrs, *self._n_values)
        self._t_fmu = 0.0

    def _update(self, t, meas):
        inst = self._inst
        if inst.n_in:
            meas.y.take(self._in_idx, out=inst.inputs)
        h = self.period
        # the FMU's clock runs on from the end of its last step; the loop's ticks are that,
        # except the last tick of a run whose duration is not a whole number of periods (its
        # command is logged, never flown)
        start = t if t >= self._t_fmu - CLOCK_RTOL * max(1.0, t) else self._t_fmu
        mark = interrupts.count()
        try:
            inst.tick(start, h)
        except FmuStepError:
            inst.fail()
            raise
        except Exception as e:  # noqa: BLE001 - an error status (FmiStatus, or FMPy's FMICallException)
            status = getattr(e, "status", None)
            inst.fail(status)
            if interrupts.since(mark):  # Ctrl-C / SIGTERM raised inside a Python FMU's own step
                raise KeyboardInterrupt from None
            what = f"returned status {status} ({_STATUS.get(status, 'illegal')})" if status is not None else f"failed ({one_line(e)})"
            call = f"doStep({start:.6g} s, {h:.6g} s)"
            fn = getattr(e, "function", "DoStep")
            call = call if fn.endswith("DoStep") else f"{fn} (in the step {call})"
            raise FmuStepError(f"{call} {what}{inst.said()}") from None
        self._t_fmu = start + h
        out = inst.outputs.tolist()  # Python floats: cheaper to check and hand over than arrays
        cmd = self._cmd_of(out)
        if self._n_cmd == 1:
            cmd = (cmd,)
        q = self._q_of(out) if self._q_of is not None else ()
        if not (all(map(math.isfinite, cmd)) and all(map(math.isfinite, q))):
            i = next(p for p in self._out_names if not math.isfinite(out[p]))
            raise FmuStepError(f"output '{self._out_names[i]}' is {out[i]} after doStep({start:.6g} s, {h:.6g} s)")
        if q:
            self.q_ref_BN = np.array(q)
        return cmd

    def summary(self) -> dict:
        return {"fmu": self.name, "fmi_version": str(self.unit.md.fmiVersion)}


#: FMI status codes (the same numbers in FMI 2 and 3)
_STATUS = {0: "ok", 1: "warning", 2: "discard", 3: "error", 4: "fatal", 5: "pending"}


def _a(word: str) -> str:
    return f"an {word}" if word[:1] in "aeiou" else f"a {word}"


#: FMU type -> (Python types accepted, conversion); bool is refused where a number is wanted
_TYPES = {
    "Real": ((int, float), float), "Float64": ((int, float), float), "Float32": ((int, float), float),
    "Integer": ((int,), int), "Enumeration": ((int,), int), "Int8": ((int,), int), "UInt8": ((int,), int),
    "Int16": ((int,), int), "UInt16": ((int,), int), "Int32": ((int,), int), "UInt32": ((int,), int),
    "Int64": ((int,), int), "UInt64": ((int,), int),
    "Boolean": ((bool,), bool), "String": ((str,), str),
}


def _typed(ctrl: FmuController, where: str, var, value):
    accepted, conv = _TYPES.get(var.type, ((), None))
    if conv is None:
        raise ctrl._err(where, f"parameter '{var.name}' is {var.type}: "
                        "stationbed sets Real/Float, Integer, Boolean and String parameters")
    if isinstance(value, bool) and conv is not bool or not isinstance(value, accepted):
        raise ctrl._err(where, f"parameter '{var.name}' is {var.type}, got {value!r} ({type(value).__name__})")
    if conv is float and not math.isfinite(float(value)):
        raise ctrl._err(where, f"parameter '{var.name}' must be finite, got {value!r}")
    return conv(value)
