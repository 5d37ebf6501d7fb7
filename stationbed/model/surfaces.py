"""Flat plates for the aerodynamic and solar-radiation torques (issue 14).

A scene's ``[[surface]]`` tables become *plates*: a box is its six one-sided outward faces.
Each plate is attached to the body (index -1) or to appendage k. The plates are part of the
model's structure (``Structure.surfaces``, one tuple per plate, :data:`PLATE_FIELDS`): their
numbers are folded into the generated code as constants, so an axis-aligned normal or a centre
on an axis costs nothing, and a scene with other surfaces compiles its own code.

* ``area`` [m²]; ``n`` the unit normal and ``c`` the centre, in the attachment's axes (B for
  the body, with body coordinates; P for an appendage, from its mass centre);
* ``rho``: unused (zeros), kept so the tuple's layout stays;
* ``two_sided`` (0 or 1), ``cd`` the drag coefficient, ``specular`` and ``diffuse`` fractions.

No plate constant depends on the mass properties: the composite mass centre ``r_O`` and each
appendage's mass centre ``a_k`` (body coordinates) come from the parameter vector (slice
``surf_O``), so a Monte Carlo that disperses masses or mass centres keeps one compiled system.
In B at time t: ``n_B = C_PBᵀ n``, ``r_B = (a_k - r_O) + C_PBᵀ c`` (``n_B = n``,
``r_B = c - r_O`` on the body). O is fixed in B: the arrays are balanced about their joint axes, so turning them does
not move the composite mass centre (an elastic array's deformation does not move its plates).

Forces, with ``w = max(n̂·x, 0)`` (one-sided) or ``|n̂·x|`` (two-sided):

* drag, free-molecular flat plate with a drag coefficient (no lift):
  ``F = -½ ρ cd A w v_rel``, ``w`` with ``x = v_rel`` (so ``½ρ|v|² A cos θ cd`` along ``-v̂``);
* solar radiation pressure (Wertz 1978 Eq. 17-10, Montenbruck & Gill 2000 Eq. 3.72 with the
  diffuse term): ``F = -P A [c_e (1 - ε_s) ŝ + (2 ε_s c_e + 2 ε_d / 3) g n̂]``, ``c_e = w``
  with ``x = ŝ``, ``g = c_e`` (one-sided) or ``n̂·ŝ`` (two-sided: the lit face's normal);
* torque about O: ``Σ r_B × F``. Plates do not shadow each other.

The symbolic functions take casadi; :func:`scene_plates` is numeric.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import casadi as ca
import numpy as np

from ..scene import Surface
from ..scene.docking import mass_centre_B, vehicle_in_B

__all__ = ["PLATE_FIELDS", "Plate", "scene_plates", "surface_origin_params", "vehicle_places", "default_surfaces", "plates_B", "aero_torque_B", "srp_torque_B"]

#: the numbers of one plate (after its attachment), in order
PLATE_FIELDS = ("area", "n_x", "n_y", "n_z", "c_x", "c_y", "c_z", "rho_x", "rho_y", "rho_z",
                "two_sided", "cd", "specular", "diffuse")


class Plate(NamedTuple):
    """One plate at time t, B axes (casadi)."""

    area: Any
    n_B: Any
    r_B: Any
    two_sided: bool
    cd: Any
    specular: Any
    diffuse: Any


def default_surfaces(scene) -> list[dict]:
    """Surfaces for a scene with aero or SRP but no ``[[surface]]`` (a first look).

    The body is the uniform box of its inertia (edges ``a² = 6 (J_yy + J_zz - J_xx)/m`` and
    cyclically) at its mass centre; each appendage is a two-sided plate in its P x-y plane (normal
    +z of P, the sun-facing normal) at its mass centre, of the area of the uniform thin plate of
    its inertia, ``12 sqrt(J_xx J_yy) / m``; an appendage with a ``wing`` has its own plate
    (``Scene.surfaces``), none here. Coefficients are the defaults.
    """
    J = np.diag(np.array(scene.body.inertia, dtype=float))
    m = scene.body.mass
    edges = [float(np.sqrt(max(6.0 * (J[(i + 1) % 3] + J[(i + 2) % 3] - J[i]) / m, 1e-4))) for i in range(3)]
    out = [{"on": "body", "size": edges, "centre": list(scene.body.cm)}]
    for a in (a for a in scene.appendage if a.wing is None):
        Jp = np.diag(a.inertia_P)
        out.append({"on": a.name, "area": float(12.0 * np.sqrt(Jp[0] * Jp[1]) / a.mass), "normal": [0.0, 0.0, 1.0],
                    "centre": [0.0, 0.0, 0.0], "two_sided": True})
    return out


def _faces(size, centre):
    """The six outward faces of a box: (area, normal, centre)."""
    out = []
    for i in range(3):
        j, k = (i + 1) % 3, (i + 2) % 3
        for sign in (1.0, -1.0):
            n = np.zeros(3)
            n[i] = sign
            out.append((size[j] * size[k], n, np.asarray(centre, float) + 0.5 * size[i] * n))
    return out


def scene_plates(scene) -> tuple[tuple[float, ...], ...]:
    """The scene's plates, one tuple per plate: its attachment (-1 body, k appendage), then
    :data:`PLATE_FIELDS` (plain floats, hashable: they are part of the model's structure).

    Parameters
    ----------
    scene : stationbed.scene.Scene
    """
    surfaces = scene.surfaces if scene.surface else [Surface(**d) for d in default_surfaces(scene)] + scene.surfaces
    names = scene.appendage_names
    out = []
    rho = np.zeros(3)  # the mass centres are parameters (surface_origin_params)
    shift = np.zeros(3)
    placed = [(s, -1 if s.on == "body" else names.index(s.on), None, shift) for s in surfaces]
    for j, (vehicle, port) in enumerate(vehicle_places(scene)):  # issue 35: -2 - j, on while docked there
        _, _, _, C_BV = vehicle_in_B(vehicle, port)
        placed += [(s, -2 - j, C_BV, -np.asarray(port.position, float)) for s in vehicle.surface]
    for s, k, C, off in placed:
        if s.size is not None:
            faces, two = _faces(s.size, s.centre), 0.0
        else:
            n = np.asarray(s.normal, float)
            faces, two = [(s.area, n / np.linalg.norm(n), np.asarray(s.centre, float))], float(s.two_sided)
        _, spec, diff = s.fractions
        for area, n, c in faces:
            if C is not None:  # a vehicle's plate: V axes from its interface -> B axes, body coordinates
                n, c = C @ n, C @ c
            out.append(tuple(float(v) for v in (k, area, *n, *(c - off), *rho, two, s.cd, spec, diff)))
    return tuple(out)


def vehicle_places(scene) -> list[tuple]:
    """``(vehicle, port)`` for every vehicle with surfaces and every port: their plates are in
    the structure from t = 0 (attachment ``-2 - j``), each on only while that vehicle is docked
    at that port (``surf_O``'s on flags), so a docking keeps the compiled system."""
    return [(v, p) for v in scene.vehicle if v.surface for p in scene.port]


def surface_origin_params(scene) -> np.ndarray:
    """The ``surf_O`` parameters: the composite mass centre ``r_O``, then each appendage's mass
    centre ``a_k`` (body coordinates [m]), then a vehicle plate set's on flag (1 while that
    vehicle is docked at that port, :func:`vehicle_places`), shape (3 + 3 n_app + n_places,)."""
    r_O = mass_centre_B(scene)
    on = [1.0 if v.port == p.name else 0.0 for v, p in vehicle_places(scene)]
    return np.concatenate([np.asarray(r_O, float)] + [np.asarray(a.cm, float) for a in scene.appendage] + [on])


def plates_B(specs, arrays, origin) -> list[Plate]:
    """The plates in B at time t (casadi, the plates' numbers as constants).

    Parameters
    ----------
    specs : tuple of tuple  :func:`scene_plates`.
    arrays : list of ArrayState  The arrays at t (their ``C_PB``).
    origin : casadi SX, shape (3 + 3 n_app,)  :func:`surface_origin_params` as parameters.
    """
    out = []
    r_O = origin[0:3]
    n_app = len(arrays)
    for q in specs:
        k = int(q[0])
        n, c = ca.SX(ca.DM(q[2:5])), ca.SX(ca.DM(q[5:8])) - r_O
        area = q[1]
        if k >= 0:
            C_BP = arrays[k].C_PB.T
            rho = origin[3 + 3 * k : 6 + 3 * k] - r_O
            n, c = _times(C_BP, q[2:5]), rho + _times(C_BP, q[5:8])
        elif k <= -2:  # a vehicle's plate at a port: its area times the on flag
            area = q[1] * origin[3 + 3 * n_app + (-2 - k)]
        out.append(Plate(area, n, c, bool(q[11]), q[12], q[13], q[14]))
    return out


def _times(M, v):
    """``M v`` for a casadi 3x3 ``M`` and a constant 3-vector ``v``, skipping its zeros."""
    terms = [M[:, j] * v[j] for j in range(3) if v[j] != 0.0]
    if not terms:
        return ca.SX.zeros(3)
    out = terms[0]
    for t in terms[1:]:
        out = out + t
    return out


def aero_torque_B(plates, v_rel_B, density):
    """Aerodynamic force and torque about O, B components (casadi (3, 1) each).

    Parameters
    ----------
    plates : list of Plate  :func:`plates_B`.
    v_rel_B : casadi SX, shape (3, 1)  Velocity of O relative to the air, B components [m/s].
    density : casadi SX  Air density [kg/m³].

    Returns
    -------
    force_B [N], torque_B [N m]
    """
    k_sum, kr_sum = 0, ca.SX.zeros(3)
    for pl in plates:
        vn = ca.dot(pl.n_B, v_rel_B)
        k = (pl.cd * pl.area) * (ca.fabs(vn) if pl.two_sided else ca.fmax(vn, 0))  # cd A |v| cos θ, windward side
        k_sum = k_sum + k
        kr_sum = kr_sum + k * pl.r_B
    half_rho_v = -0.5 * density * v_rel_B
    return k_sum * half_rho_v, ca.cross(kr_sum, half_rho_v)


def srp_torque_B(plates, s_B, pressure):
    """Solar radiation force and torque about O, B components (casadi (3, 1) each).

    Parameters
    ----------
    plates : list of Plate  :func:`plates_B`.
    s_B : casadi SX, shape (3, 1)  Unit vector to the sun, B components.
    pressure : casadi SX  Radiation pressure P at the station, times the lit fraction [N/m²].

    Returns
    -------
    force_B [N], torque_B [N m]
    """
    F_sum, L_sum = ca.SX.zeros(3), ca.SX.zeros(3)
    for pl in plates:
        cos = ca.dot(pl.n_B, s_B)
        lit = ca.fabs(cos) if pl.two_sided else ca.fmax(cos, 0)
        g = cos if pl.two_sided else lit
        pa = -pressure * pl.area
        F = (pa * lit * (1 - pl.specular)) * s_B + (pa * g * (2 * pl.specular * lit + (2.0 / 3.0) * pl.diffuse)) * pl.n_B
        F_sum = F_sum + F
        L_sum = L_sum + ca.cross(pl.r_B, F)
    return F_sum, L_sum
