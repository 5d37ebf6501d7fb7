"""Shipped attitude laws (DESIGN §7). ``CONTROLLERS`` maps scene names to classes.

Write your own: subclass :class:`stationbed.controller.Controller` (see ``example_hold.py``)
and name it in a scene as ``name = "your_module:YourClass"``, or register it here.

Every module listed in ``MODULES`` is imported and each :class:`Controller` subclass it defines
with a ``name`` is registered (an import error is an error, never skipped).
"""

from __future__ import annotations

import importlib
import inspect

from stationbed.controller import Controller

MODULES = ("pd", "lqr", "momentum_manager", "mpc", "torque_command", "example_hold")


def _collect() -> dict[str, type[Controller]]:
    from pathlib import Path

    here = Path(__file__).parent
    reg = {}
    for mod_name in MODULES:
        if not (here / f"{mod_name}.py").exists():
            continue
        mod = importlib.import_module(f"{__name__}.{mod_name}")
        for _, cls in inspect.getmembers(mod, inspect.isclass):
            if issubclass(cls, Controller) and cls.name and cls.__module__ == mod.__name__:
                reg[cls.name] = cls
    return reg


CONTROLLERS = _collect()

__all__ = ["CONTROLLERS", "MODULES"]
