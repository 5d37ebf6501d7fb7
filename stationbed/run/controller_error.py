"""The controller's error and the one-line form of a message (:mod:`.controller` re-exports them;
here so that :mod:`.law_state` and :mod:`.law_compiled`, which the controller uses, need not
import it)."""

from __future__ import annotations

__all__ = ["ControllerError", "ControllerFailure", "one_line", "law_failure", "replan_failure"]


class ControllerError(ValueError):
    """A controller that cannot be built (unknown name, bad parameters)."""


class ControllerFailure(Exception):
    """The controller raised or returned a bad command at time ``t`` [s]; ``reason`` is one line
    (:mod:`.composition` re-exports it).

    When it raised, that exception is this one's ``__cause__`` (with its traceback)."""
    def __init__(self, t: float, reason: str):
        super().__init__(reason)
        self.t = t
        self.reason = reason


def one_line(e: BaseException | str) -> str:
    """An exception's message (or any text) on one line: its lines stripped, joined by " | "."""
    return " | ".join(line.strip() for line in str(e).splitlines() if line.strip())


def law_failure(ctrl, t: float, e: BaseException) -> ControllerFailure:
    """The failure at ``t`` of the law ``ctrl`` whose update raised ``e`` (raise it ``from e``)."""
    return ControllerFailure(t, f"controller '{ctrl.name}' raised {type(e).__name__}: {one_line(e)}")


def replan_failure(ctrl, t: float, e: BaseException) -> ControllerFailure:
    """The failure at ``t`` of the law ``ctrl`` whose design on the plant with a detected failure
    (its ``_replan``, else its ``_reset``) raised ``e`` (raise it ``from e``)."""
    hook = "_replan" if hasattr(ctrl, "_replan") else "_reset"
    return ControllerFailure(t, f"controller '{ctrl.name}' raised {type(e).__name__} in {hook} on the "
                                f"plant with the failure detected: {one_line(e)}")
