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
from pathlib import Path

import numpy as np

from .controller import Controller, measurement_layout, one_line
from .fmu_unit import FmuError, FmuStepError, load_unit

__all__ = ["FmuController", "FmuError", "FmuStepError", "COMMAND_OUTPUTS"]

#: command kind -> the output field that carries it
COMMAND_OUTPUTS = {"torque": "tau_cmd", "gimbal_rates": "gimbal_rate_cmd"}
#: the optional output of the reference attitude (scalar first)
Q_REF = "q_ref_BN"
#: FMU parameters set from the plant facts when the scene does not give them: name -> size
PLANT_PARAMS = {"inertia_O_B": 9, "mean_motion": 1, "period": 1}
#: the measurement's fields (sizes of gimbal, alpha, beta: per scene)
MEASUREMENT_FIELDS = tuple(measurement_layout(0, 0))
_ELEMENT = re.compile(r"^(.*)\[(\d+)\]$")
#: how many near names an error lists
NEAR = 4


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

    def _check_var(self, where: str, name: str, causality: str) -> None:
        """``name`` is an FMU variable of ``causality`` holding a Real/Float64."""
        var = self._vars.get(name)
        if var is None:
            raise self._err(where, f"has no variable '{name}'{_near(name, self._of(causality))}")
        if var.causality != causality:
            role = "a measurement drives an FMU input" if causality == "input" else "the command is an FMU output"
            raise self._err(where, f"variable '{name}' is {_a(var.causality)}, not {_a(causality)} ({role})")
        if not _is_float(var) or getattr(var, "dimensions", None):
            kind = f"an array {var.type}" if getattr(var, "dimensions", None) else var.type
            raise self._err(where, f"variable '{name}' is {kind}: the loop exchanges scalar Real (FMI 2) / Float64 (FMI 3) values")

    def _expand(self, where: str, base: str, n: int) -> list[str]:
        """``base[0..n-1]`` or ``base[1..n]``, whichever the FMU has in full."""
        for b in (0, 1):
            names = [f"{base}[{b + i}]" for i in range(n)]
            if all(x in self._vars for x in names):
                return names
        raise self._err(where, f"has no variables {base}[0..{n - 1}] or {base}[1..{n}]{_near(base + '[0]', self._vars)}")

    def _element_map(self, sizes: dict[str, int]) -> dict[str, str]:
        """Loop element -> FMU variable, from ``[controller.variables]`` (elements and fields)."""
        out = {}
        for key, value in self.variables.items():
            field, i = _split(key)
            where = f"controller.variables.{key}"
            n = sizes[field]
            if i is None:
                causality = "input" if field in MEASUREMENT_FIELDS else "output"
                for j, name in enumerate(self._expand(where, value, n)):
                    self._check_var(where, name, causality)
                    out[f"{field}[{j}]"] = name
            elif i >= n:
                raise FmuError(f"{where}: the scene's {field} has {n} elements ({field}[0..{n - 1}])" if n else
                               f"{where}: the scene has no {field} (no such element)")
            else:
                out[key] = value
        return out

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
            if isinstance(value, list):
                pairs = list(zip(self._expand(where, name, len(value)), value))
            else:
                pairs = [(name, value)]
            for vname, v in pairs:
                out.append(self._param(where, vname, v))
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
            names = [name] if n == 1 and name in self._vars else None
            if names is None:
                try:
                    names = self._expand("", name, n)
                except FmuError:
                    continue  # the FMU does not take this fact
            for vname, v in zip(names, facts[name]):
                if self._vars[vname].causality == "parameter":
                    out.append(self._param(f"plant fact {name}", vname, v))
        return out

    # -- a run -------------------------------------------------------------------------------
    def _bind(self, plant) -> None:
        ng, na = plant.n_gimbals, len(plant.scene.appendage) if plant.scene is not None else 0
        layout = measurement_layout(ng, na)
        sizes = {f: k for f, (o, k) in layout.items()}
        sizes.update(tau_cmd=3, gimbal_rate_cmd=ng, q_ref_BN=4)
        emap = self._element_map(sizes)
        # inputs: each FMU input driven by exactly one measurement element
        driver: dict[str, str] = {}
        for el, fv in emap.items():
            if _split(el)[0] in MEASUREMENT_FIELDS:
                if fv in driver:
                    raise self._err(f"controller.variables.{el}", f"input '{fv}' is driven twice ({driver[fv]} and {el})")
                driver[fv] = el
        elements = {f"{f}[{i}]": o + i for f, (o, k) in layout.items() for i in range(k)}
        for el in elements:
            if el not in emap and el not in driver and el in self._vars and self._vars[el].causality == "input":
                driver[el] = el
        inputs = self._of("input")
        for name in inputs:
            if name not in driver:
                raise self._err("controller.variables", f"input '{name}' is driven by no measurement: name one in "
                                f"[controller.variables], e.g. \"q_BN[0]\" = \"{name}\"{_near(name, elements)}")
            self._check_var(f"controller.variables.{driver[name]}", name, "input")
        self._in_names = inputs
        self._in_idx = np.array([elements[driver[n]] for n in inputs], dtype=np.intp)
        # outputs: the command, then the reference attitude when the FMU gives it
        field = COMMAND_OUTPUTS[self.command]
        cmd = [emap.get(f"{field}[{i}]", f"{field}[{i}]") for i in range(sizes[field])]
        for i, name in enumerate(cmd):
            self._check_var(f"controller.variables.{field}[{i}]", name, "output")
        q_names = [emap.get(f"{Q_REF}[{i}]", f"{Q_REF}[{i}]") for i in range(4)]
        given = [n in self._vars and self._vars[n].causality == "output" for n in q_names]
        explicit = any(_split(k)[0] == Q_REF for k in self.variables)
        if explicit or any(given):
            for i, name in enumerate(q_names):
                self._check_var(f"controller.variables.{Q_REF}[{i}]", name, "output")
        else:
            q_names = []
        self._out_names = cmd + q_names
        self._n_cmd = len(cmd)
        self._has_q_ref = bool(q_names)
        vr = lambda names: [self._vars[n].valueReference for n in names]  # noqa: E731
        self._in_vrs, self._out_vrs = vr(inputs), vr(self._out_names)

    def _reset(self, plant) -> None:
        self._bind(plant)
        params = self._plant_params(plant) + self._param_values
        inst = self._inst
        if inst is None or inst.broken:
            inst = self._inst = self.unit.acquire(self)
        try:
            inst.start(params)
        except Exception as e:  # noqa: BLE001 - the FMU refused its parameters or its initialisation
            inst.broken = True
            raise FmuError(f"FMU '{self.name}': initialisation at t = 0 failed ({one_line(e)}{inst.said()})") from None
        inst.bind(self._in_vrs, self._out_vrs)
        self._t_fmu = 0.0

    def _update(self, t, meas):
        inst = self._inst
        if inst.n_in:
            meas.y.take(self._in_idx, out=inst.inputs)
        h = self.period
        # the FMU's clock runs on from the end of its last step; the loop's ticks are that,
        # except the last tick of a run whose duration is not a whole number of periods (its
        # command is logged, never flown)
        start = t if t >= self._t_fmu - 1e-9 * max(1.0, t) else self._t_fmu
        try:
            inst.tick(start, h)
        except FmuStepError:
            inst.broken = True
            raise
        except Exception as e:  # noqa: BLE001 - an error status (FmiStatus, or FMPy's FMICallException)
            inst.broken = True
            status = getattr(e, "status", None)
            what = f"returned status {status} ({_STATUS.get(status, 'illegal')})" if status is not None else f"failed ({one_line(e)})"
            call = f"doStep({start:.6g} s, {h:.6g} s)"
            fn = getattr(e, "function", "DoStep")
            call = call if fn.endswith("DoStep") else f"{fn} (in the step {call})"
            raise FmuStepError(f"{call} {what}{inst.said()}") from None
        self._t_fmu = start + h
        out = inst.outputs.tolist()  # Python floats: cheaper to check and hand over than arrays
        if not all(map(math.isfinite, out)):
            i = next(i for i, v in enumerate(out) if not math.isfinite(v))
            raise FmuStepError(f"output '{self._out_names[i]}' is {out[i]} after doStep({start:.6g} s, {h:.6g} s)")
        n = self._n_cmd
        if self._has_q_ref:
            self.q_ref_BN = np.array(out[n : n + 4])
        return tuple(out[:n])

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
    if conv is None or getattr(var, "dimensions", None):
        raise ctrl._err(where, f"parameter '{var.name}' is {var.type}{' (array)' if getattr(var, 'dimensions', None) else ''}: "
                        "stationbed sets scalar Real/Float, Integer, Boolean and String parameters")
    if isinstance(value, bool) and conv is not bool or not isinstance(value, accepted):
        raise ctrl._err(where, f"parameter '{var.name}' is {var.type}, got {value!r} ({type(value).__name__})")
    if conv is float and not math.isfinite(float(value)):
        raise ctrl._err(where, f"parameter '{var.name}' must be finite, got {value!r}")
    return conv(value)
