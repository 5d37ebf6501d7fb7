"""The law a scene's ``[controller]`` table names, built: a Python law or an FMU (issue 23)."""

from __future__ import annotations

from pathlib import Path

from .controller import Controller, get_controller
from .fmu import FmuController
from .socket_law import SocketController

__all__ = ["build_controller"]


def build_controller(spec, base_dir: str | Path | None = None) -> Controller:
    """The controller a scene's ``[controller]`` table names, built with its period and parameters:
    a Python law (:func:`get_controller`) or, with ``fmu = "law.fmu"``, an FMI co-simulation unit
    (:class:`~stationbed.run.fmu.FmuController`, FMPy needed: the ``stationbed[fmi]`` extra) or,
    with ``port = "host:port"``, a law in another process (:class:`~.socket_law.SocketController`).

    Parameters
    ----------
    spec : ControllerSpec  The scene's ``controller`` table.
    base_dir : str or Path, optional  The scene file's folder (relative files are found there).
    """
    if getattr(spec, "port", None) is not None:  # a law in another process (issue 36, docs/socket_law.md)
        return SocketController(spec.port, period=spec.period, params=spec.params, command=spec.command,
                                timeout=spec.timeout)
    if getattr(spec, "fmu", None) is not None:
        return FmuController(spec.fmu, period=spec.period, params=spec.params, variables=spec.variables, base_dir=base_dir)
    return get_controller(spec.name, base_dir=base_dir)(period=spec.period, **spec.params)
