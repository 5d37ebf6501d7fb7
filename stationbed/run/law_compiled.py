"""A law's ``symbolic`` form, compiled: what every executor calls for a law that has one (issue 33).

The fused loop inlines the law's casadi form (:func:`.blocks.law_block`); the per-tick loop
(:meth:`.controller.Controller.tick_update`), :meth:`.controller.Controller.update` and the
lockstep loop (:meth:`.controller.Controller.update_batch`) call the same expression as one
compiled Function ``law(t, y, cp, s) -> ([command; q_ref_BN], s_next)`` (built once per law and
measurement size, generated as C through the disk cache :func:`~..core.compile.compile_functions`,
called through :class:`~..core.compile.FastCall`'s buffers). So a law is written once: its
``symbolic`` form; ``_update`` / ``update_batch`` stay for laws that cannot be symbolic.

The law's own state (``symbolic_state``, :mod:`.law_state`) is carried in the buffers between
calls and handed back with :meth:`CompiledLaw.finish` (the executors do it at the end of a run,
:meth:`~.controller.Controller.update` after each call).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..core.compile import FastCall, compile_functions
from ..core.layout import Layout
from . import law_state
from .measurement import command_fields

__all__ = ["CompiledForm", "CompiledLaw", "CompiledBatch"]

#: compiled law Functions of this process, by the serialised SX Function (the same expression
#: twice is one library, loaded once)
_FUNCS: dict[str, ca.Function] = {}


class CompiledForm:
    """What :class:`~.controller.Controller` gets from here: its ``symbolic`` form compiled."""

    def has_symbolic(self) -> bool:
        """Whether the law has a ``symbolic`` form and writes no ``_update``: then every executor
        evaluates that form compiled, and ``_update`` / ``update_batch`` are not needed."""
        return (getattr(type(self)._update, "abstract", False) and callable(getattr(self, "symbolic", None))
                and callable(getattr(self, "symbolic_params", None)))

    def compiled_law(self) -> "CompiledLaw":
        """The law's ``symbolic`` form compiled, called as ``law(t, meas) -> command`` (one per
        reset: ``reset`` clears ``_law``)."""
        law = self.__dict__.get("_law")
        if law is None:
            law = self._law = CompiledLaw(self)
        return law

    def hand_back_compiled(self) -> None:
        """Give the law the state its compiled form carried (a per-tick or lockstep run's end)."""
        for name in ("_law", "_batch_law"):
            law = self.__dict__.get(name)
            if law is not None:
                law.finish()

    def reload_compiled(self) -> None:
        """The compiled form takes the law's numbers and state again (after a replan)."""
        law = self.__dict__.get("_law")
        if law is not None:
            law.load()

    def _symbolic_batch(self, t, meas):
        """``update_batch`` of a law with only a ``symbolic`` form: every sample at once."""
        law = self.__dict__.get("_batch_law")
        if law is None:
            law = self._batch_law = CompiledBatch(self.members)
        out, self.q_ref_BN = law(t, meas)
        self.batch_failed = {}
        return self._failed_rows(out)

    def __getstate__(self):
        state = dict(self.__dict__)
        for name in ("_law", "_batch_law", "_member_meas"):  # (buffers: built again at the next call)
            state.pop(name, None)
        return state


def _function(ctrl, ny: int, ncp: int, ns: int) -> ca.Function:
    """``law(t, y, cp, s) -> (out = [command; q_ref_BN], s_next)`` compiled (the disk cache)."""
    ncmd = command_fields(ctrl.command, ctrl.plant.n_gimbals).size
    t, y, cp, s = ca.SX.sym("t"), ca.SX.sym("y", ny), ca.SX.sym("cp", ncp), ca.SX.sym("s", ns)
    cmd, q_ref, s1 = law_state.symbolic(ctrl, t, y, cp, s, ncmd)
    f = ca.Function("law", [t, y, cp, s], [ca.vertcat(cmd, q_ref), s1], ["t", "y", "cp", "s"], ["out", "s_next"])
    key = f.serialize()
    hit = _FUNCS.get(key)
    if hit is None:
        name = "".join(ch if ch.isalnum() else "_" for ch in str(ctrl.name))[:40]
        hit = _FUNCS[key] = compile_functions([f], f"law_{name}_{ny}_{ncp}_{ns}")["law"]
    return hit


def _params(ctrl) -> np.ndarray:
    return np.asarray([float(v) for v in ctrl.symbolic_params()], dtype=float)


class CompiledLaw:
    """One law's compiled ``symbolic`` form, called per tick as ``law(t, meas) -> command``
    (a tuple of floats); sets ``ctrl.q_ref_BN``; carries the law's state between calls."""

    def __init__(self, ctrl):
        self.ctrl = ctrl
        self.fc = None
        self.ny = -1

    def load(self) -> None:
        """Take the law's numbers and state now (after ``_reset`` or a replan)."""
        if self.fc is not None:
            self.fc.args[2][:] = _params(self.ctrl)
            self.fc.args[3][:] = law_state.initial(self.ctrl)

    def _build(self, ny: int) -> None:
        cp, s = _params(self.ctrl), law_state.initial(self.ctrl)
        self.fc = FastCall(_function(self.ctrl, ny, cp.size, s.size))
        self.ny = ny
        self.fc.args[2][:] = cp
        self.fc.args[3][:] = s
        self.out = _out_layout(self.fc.res[0].size - 4)
        self._cmd, self._q = self.out.slice("cmd"), self.out.slice("q_ref_BN")
        self._t, self._y, self._s = self.fc.args[0], self.fc.args[1], self.fc.args[3]
        self._out, self._s1 = memoryview(self.fc.res[0]), self.fc.res[1]
        self._trigger = self.fc._trigger

    def __call__(self, t, meas):
        y = meas.y
        if y.size != self.ny:
            self._build(y.size)
        self._t[0] = t
        self._y[:] = y
        self._trigger()
        if self._s.size:
            self._s[:] = self._s1
        out = self._out
        self.ctrl.q_ref_BN = tuple(out[self._q])
        return tuple(out[self._cmd])

    def finish(self) -> None:
        """Hand the law its state (``set_symbolic_state``), as the compiled loops do at the end."""
        if self.fc is not None:
            law_state.hand_back(self.ctrl, self._s.copy())


class CompiledBatch:
    """The compiled law mapped over a batch's samples (:meth:`.controller.Controller.batch_of`'s
    members, each with its own numbers and state): one call per tick for all of them."""

    def __init__(self, members: list):
        self.members = members
        self.fc = None

    def __call__(self, t, meas) -> tuple[np.ndarray, np.ndarray]:
        """``(commands (n, ncmd), q_ref_BN (n, 4))`` of every sample at ``t``."""
        n, ny = meas.y.shape
        if self.fc is None:
            m0 = self.members[0]
            cp = np.array([_params(m) for m in self.members])
            s = np.array([law_state.initial(m) for m in self.members]).reshape(n, -1)
            f = _function(m0, ny, cp.shape[1], s.shape[1])
            self.fc = FastCall(f.map(n, "serial"))
            self.fc.args[2][:] = cp.ravel()  # (sample i's column: its numbers, side by side)
            self.fc.args[3][:] = s.ravel()
            self.ns = s.shape[1]
            self.out = _out_layout(self.fc.res[0].size // n - 4)
            out = self.fc.res[0].reshape(n, -1)  # (views on the result buffer, made once)
            self._cmd, self._q = out[:, self.out.slice("cmd")], out[:, self.out.slice("q_ref_BN")]
            self._y = self.fc.args[1].reshape(n, ny)
        fc = self.fc
        fc.args[0][:] = t
        self._y[:] = meas.y
        fc()
        if self.ns:
            fc.args[3][:] = fc.res[1]
        return self._cmd.copy(), self._q.copy()

    def finish(self) -> None:
        """Hand each member its state."""
        if self.fc is not None and self.ns:
            s = self.fc.args[3].reshape(len(self.members), self.ns)
            for m, si in zip(self.members, s):
                law_state.hand_back(m, si.copy())


def _out_layout(ncmd: int) -> Layout:
    """The compiled law's first output: the command (``ncmd``), then ``q_ref_BN`` (4)."""
    return Layout(cmd=ncmd, q_ref_BN=4)
