"""A law's own state carried by the compiled loops (issue 22): the contract and its checks.

A law that keeps a state between ticks (an integral, a running average) can still run fused
(:mod:`.composed`: the law block's memory) by declaring it, beside ``symbolic_params``:

* ``symbolic_state() -> sequence of float``: the state now, as a flat list of floats (after
  ``_reset``: its initial value);
* ``symbolic(t, y, cp, s) -> (command, q_ref_BN, s_next)``: the command of this tick from the
  state ``s`` before it, and the state after it (what ``_update`` leaves for the next tick);
* ``set_symbolic_state(s)``: take the state back at the end of a compiled run, so that what the
  Python law reports (``summary()``) is what the compiled loop did.

The compiled loops carry ``s`` after the plant's state in the ``mapaccum`` carry (the law's
state is integrated as the plant's is: one update per tick, masked in a chunk's unused tail).
A law without ``symbolic_state`` keeps the stateless form ``symbolic(t, y, cp) -> (command,
q_ref_BN)`` (backwards compatible: every existing law and user law is unchanged).
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from .controller_error import ControllerError, one_line

__all__ = ["has_state", "initial", "symbolic", "hand_back", "law_numbers"]


def has_state(ctrl) -> bool:
    """Whether ``ctrl`` declares a state for its symbolic form (``symbolic_state``)."""
    return callable(getattr(ctrl, "symbolic_state", None))


def initial(ctrl) -> np.ndarray:
    """The law's state now, (n_s,) float64 (empty for a stateless law), checked: finite floats;
    a law with ``symbolic_state`` but no ``set_symbolic_state`` is refused (its summary would
    not see the run)."""
    if not has_state(ctrl):
        return np.zeros(0)
    if not callable(getattr(ctrl, "set_symbolic_state", None)):
        raise ControllerError(f"controller '{ctrl.name}': has symbolic_state() but no set_symbolic_state(s)")
    try:
        s = [float(v) for v in ctrl.symbolic_state()]
    except Exception as e:
        raise ControllerError(f"controller '{ctrl.name}': symbolic_state() raised {type(e).__name__}: "
                              f"{one_line(e)}") from e
    if not all(map(math.isfinite, s)):
        raise ControllerError(f"controller '{ctrl.name}': symbolic_state() is not finite: {s}")
    return np.array(s, dtype=float)


def symbolic(ctrl, t, y, cp, s, n_cmd: int):
    """``(command, q_ref_BN, s_next)`` of the law's symbolic form (``s`` and ``s_next`` empty for
    a stateless law); ControllerError naming the controller for what its code raises or returns
    wrong (the command's size, the state's)."""
    n_s = s.numel()
    try:
        if n_s:
            cmd, q_ref, s_next = ctrl.symbolic(t, y, cp, s)
            s_next = ca.vertcat(*s_next) if isinstance(s_next, (list, tuple)) else ca.vertcat(s_next)
        else:
            cmd, q_ref = ctrl.symbolic(t, y, cp)
            s_next = type(s).zeros(0, 1)
        cmd = ca.vertcat(cmd)
    except Exception as e:  # the user's casadi code: name the controller, keep the traceback
        raise ControllerError(f"controller '{ctrl.name}': symbolic() raised {type(e).__name__}: {one_line(e)}") from e
    if cmd.numel() != n_cmd:
        raise ControllerError(f"controller '{ctrl.name}': symbolic() returned {cmd.numel()} command values, "
                              f"expected {n_cmd} ({ctrl.command})")
    if s_next.numel() != n_s:
        raise ControllerError(f"controller '{ctrl.name}': symbolic() returned a state of {s_next.numel()} values, "
                              f"expected {n_s} (symbolic_state())")
    return cmd, q_ref, s_next


def hand_back(ctrl, s) -> None:
    """Give the law the state the compiled loop carried (``set_symbolic_state``)."""
    if len(s):
        ctrl.set_symbolic_state(np.array(s, dtype=float))


def law_numbers(ctrl):
    """The law's numbers for its symbolic form, ``ctrl.symbolic_params()`` (empty for a law
    without one: the composition's key counts them); ControllerError naming the controller if
    the user's code raises."""
    if not callable(getattr(ctrl, "symbolic", None)):
        return ()
    try:
        return ctrl.symbolic_params()
    except Exception as e:
        raise ControllerError(f"controller '{ctrl.name}': symbolic_params() raised {type(e).__name__}: {one_line(e)}") from e
