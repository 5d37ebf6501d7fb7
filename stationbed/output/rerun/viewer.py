"""The rerun viewer that ``stationbed replay`` starts: which binary, how a user types it, and
whether a native window can open here."""

from __future__ import annotations

import os
import sys
from pathlib import Path

__all__ = ["rerun_binary", "rerun_command", "has_display", "RERUN_BINARY_ENV"]

#: Environment variable naming the rerun viewer binary `stationbed replay` starts (tests, or
#: a viewer outside the venv); default: the binary rerun-sdk bundles, then `rerun` on PATH.
RERUN_BINARY_ENV = "STATIONBED_RERUN"


def rerun_binary() -> str | None:
    """The rerun viewer executable: $STATIONBED_RERUN, rerun-sdk's bundled binary, or PATH."""
    import importlib.util
    import shutil

    override = os.environ.get(RERUN_BINARY_ENV)
    if override:
        return override
    spec = importlib.util.find_spec("rerun_cli")  # the package rerun-sdk installs the binary in
    if spec is not None and spec.origin:
        exe = Path(spec.origin).parent / ("rerun.exe" if sys.platform.startswith("win") else "rerun")
        if exe.is_file():
            return str(exe)
    venv = Path(sys.executable).parent / "rerun"
    return str(venv) if venv.is_file() else shutil.which("rerun")


def rerun_command(exe: str | None) -> str:
    """How a user types the viewer: the override, else ``rerun`` when on PATH, else the venv's."""
    import shlex
    import shutil

    if os.environ.get(RERUN_BINARY_ENV) or exe is None:
        return shlex.quote(exe or "rerun")
    if shutil.which("rerun"):
        return "rerun"
    venv = Path(sys.executable).parent / "rerun"
    return shlex.quote(str(venv) if venv.is_file() else exe)


def has_display() -> bool:
    """False on Linux/BSD without an X or Wayland display (the native viewer cannot open)."""
    if sys.platform.startswith(("win", "darwin")):
        return True
    return any(os.environ.get(v) for v in ("DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET"))
