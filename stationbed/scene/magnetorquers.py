"""The scene table of the magnetic torquers (issue 33 item 6; physics in
:mod:`stationbed.loop.magnetorquers`, docs/loop.md "Adding an actuator: a worked example")::

    [magnetorquers]
    max_dipole_Am2 = [4000.0, 4000.0, 4000.0]   # A m², each rod's largest dipole (rods along B x, y, z)

The scene holds it as ``Scene.magnetorquers``; the closed loop flies it before the thrusters
and the CMG cluster (the rods take the part of the law's request they can make).
"""

from __future__ import annotations

from pydantic import model_validator

from stationbed.scene.base import FieldError, Strict, Vec3

__all__ = ["Magnetorquers", "check_magnetorquers"]


class Magnetorquers(Strict):
    """``[magnetorquers]``: three magnetic torque rods along the body axes."""

    max_dipole_Am2: Vec3  # A m², each rod's largest dipole moment (x, y, z rods)

    @model_validator(mode="after")
    def _positive(self):
        bad = [f"{c} = {v!r}" for c, v in zip("xyz", self.max_dipole_Am2) if not v > 0.0]
        if bad:
            raise FieldError("max_dipole_Am2", f"every rod's largest dipole must be > 0 A m², got {', '.join(bad)}")
        return self


def check_magnetorquers(scene) -> None:
    """``[magnetorquers]`` agrees with the rest of the scene: the field is read at the orbit's
    position, and the rods are commanded by the closed loop's torque request."""
    if scene.magnetorquers is None:
        return
    if scene.orbit is None:
        raise FieldError("magnetorquers", "the Earth's field is read at the station's position: add an [orbit] table")
    if scene.controller is None:
        raise FieldError("magnetorquers", "magnetic torquers are commanded by the closed loop: add a [controller] table")
