"""Shipped attitude laws (DESIGN §7). ``CONTROLLERS`` maps scene names to classes.

Write your own: subclass :class:`stationbed.controller.Controller` (see ``example_hold.py``)
and name it in a scene as ``name = "your_module:YourClass"``.
"""

from .pd import PD

CONTROLLERS = {c.name: c for c in (PD,)}

__all__ = ["CONTROLLERS", "PD"]
