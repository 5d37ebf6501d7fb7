"""The controller's error and the one-line form of a message (:mod:`.controller` re-exports them;
here so that :mod:`.law_state` and :mod:`.law_compiled`, which the controller uses, need not
import it)."""

from __future__ import annotations

__all__ = ["ControllerError", "one_line"]


class ControllerError(ValueError):
    """A controller that cannot be built (unknown name, bad parameters)."""


def one_line(e: BaseException | str) -> str:
    """An exception's message (or any text) on one line: its lines stripped, joined by " | "."""
    return " | ".join(line.strip() for line in str(e).splitlines() if line.strip())
