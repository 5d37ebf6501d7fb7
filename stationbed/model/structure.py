"""What a scene's equations contain (:class:`Structure`) and the parameter vector's layout.

Two scenes with equal structure share compiled code; their numbers differ only in the parameter
vector ``p``, whose names and slices :class:`ParamLayout` declares once.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

from .cmg import CmgModel, get_geometry
from .orbit import orbit_kind, orbit_size
from .surfaces import scene_plates
from .torques import TORQUES

__all__ = ["Structure", "ParamLayout", "JOINTS"]


@dataclass(frozen=True)
class Structure:
    """What a scene's equations contain; two scenes with equal structure share compiled code.

    Attributes
    ----------
    n_app : int  Number of articulated arrays.
    orbit : bool  Whether the scene has an orbit (its numbers are in ``p``).
    torques : tuple of str  The symbolic external-torque kinds in the equations
        (:data:`~stationbed.model.torques.TORQUES` names, in registry order); the held kinds
        (``constant``) enter through the held input and are not part of the structure.
    joints : tuple  Per appendage ``((kind, n_steps) for alpha, (kind, n_steps) for beta)`` with
        kind ``"p"`` (profile with ``n_steps`` rate steps) or ``"s"`` (sun-tracking drive, a state).
    sun : bool  Whether the scene has a sun direction (in ``p``).
    cmg : tuple or None  ``(kind, n_units, steering, unit_faults)`` of the CMG cluster (steering
        ``"none"`` for a cluster without gimbals; ``unit_faults``: the scene has ``[[fault]]``
        tables, whose steps may change a unit's rotor or rate cap, :class:`~stationbed.model.cmg.CmgModel`).
    modes : tuple of int  Elastic modes per appendage (all 0: a rigid scene, whose equations and
        key do not change).
    orbit_kind : tuple  ``()`` for a circular orbit (or none), ``(newton_steps, j2)`` for a
        two-body orbit (:func:`~stationbed.model.orbit.orbit_kind`).
    surfaces : tuple  The plates of the aero/SRP surfaces (:func:`~stationbed.model.surfaces.scene_plates`:
        attachment and numbers, folded into the generated code); empty without those kinds.
    eclipse : str  The shadow model (``"cylindrical"``, ``"conical"``; ``""``: always lit).

    A sun-tracking joint whose night mode is the glider has kind ``"g"``.
    """

    n_app: int
    orbit: bool
    torques: tuple = ()
    joints: tuple = ()
    sun: bool = False
    cmg: tuple | None = None
    modes: tuple = ()
    orbit_kind: tuple = ()
    surfaces: tuple = ()
    eclipse: str = ""

    def __post_init__(self):
        order = [k for k in TORQUES if k in self.torques]
        if list(self.torques) != order or any(not TORQUES[k].symbolic for k in self.torques):
            raise ValueError(f"torques must be symbolic kinds in registry order {tuple(TORQUES)}, got {self.torques}")

    @classmethod
    def of(cls, scene) -> "Structure":
        """The structure of ``scene`` (a :class:`stationbed.scene.Scene`)."""

        def joint(j):
            if j.tracked:
                return ("g", 0) if j.night == "glider" else ("s", 0)
            return ("p", len(j.rate_step))

        c = scene.cmg
        plated = any(TORQUES[t.kind].needs_env for t in scene.torque)
        return cls(
            n_app=len(scene.appendage),
            orbit=scene.orbit is not None,
            torques=tuple(k for k, kind in TORQUES.items() if kind.symbolic and kind.present(scene)),
            joints=tuple((joint(a.alpha), joint(a.beta)) for a in scene.appendage),
            sun=scene.sun is not None,
            cmg=None if c is None else (c.kind, c.n_units, c.steering if get_geometry(c.kind).gimbals_per_unit else "none",
                                        bool(scene.fault)),
            modes=tuple(len(a.mode) for a in scene.appendage) if any(a.mode for a in scene.appendage) else (),
            orbit_kind=orbit_kind(scene.orbit) if scene.orbit is not None else (),
            surfaces=scene_plates(scene) if plated else (),
            eclipse="" if scene.sun is None or scene.sun.eclipse == "none" else scene.sun.eclipse,
        )

    @property
    def key(self) -> str:
        """A name of the structure (it names the cached library), e.g. ``a2o1g1h0jp0p0s0``."""
        j = "".join(f"{k}{n}" for a in self.joints for k, n in a)
        c = "" if self.cmg is None else f"c{self.cmg[0]}{self.cmg[1]}{self.cmg[2]}{'u' if self.cmg[3:4] != (False,) else ''}"
        f = "" if not self.modes else "f" + "_".join(str(n) for n in self.modes)
        trq = "".join(kind.key(k in self.torques) for k, kind in TORQUES.items() if kind.symbolic)
        k = "" if not self.orbit_kind else f"k{self.orbit_kind[0]}{'j' if self.orbit_kind[1] else ''}"
        env = "" if not self.eclipse else f"E{self.eclipse[:3]}"
        if self.surfaces:  # the plates' numbers are in the code: a digest of them names it
            env += f"S{len(self.surfaces)}_" + hashlib.sha1(repr(self.surfaces).encode()).hexdigest()[:10]
        return f"a{self.n_app}o{int(self.orbit)}{k}{trq}j{j}s{int(self.sun)}{c}{f}{env}"

    def n_modes(self, k: int) -> int:
        """Number of elastic modes of appendage ``k``."""
        return self.modes[k] if self.modes else 0


JOINTS = ("alpha", "beta")


class ParamLayout:
    """Names and slices of the parameter vector ``p`` (declared once, owns the indices).

    In order: ``I0`` (9), per appendage ``J<k>`` (9), its joints ``alpha<k>``, ``beta<k>`` and,
    when flexible, ``rho<k>`` (3) and ``modes<k>``; ``mtot`` (flexible scenes); ``orbit`` (6);
    one slice per symbolic torque kind with numbers, named by the kind; ``sun`` (3); ``surf_O``
    (3 + 3 n_app, with aero/SRP plates: the mass centres they are measured from); ``shadow``
    (1, with an eclipse model); ``cmg``.

    Parameters
    ----------
    structure : Structure

    Attributes
    ----------
    slices : dict of str to slice  Where each named block lies in ``p``.
    size : int  Length of ``p``.
    """

    def __init__(self, structure: Structure):
        self.slices: dict[str, slice] = {}
        n = 0

        def add(name, size):
            nonlocal n
            self.slices[name] = slice(n, n + size)
            n += size

        add("I0", 9)  # hub + all parallel-axis terms, about O, B axes [kg m²]
        for k in range(structure.n_app):
            add(f"J{k}", 9)  # array inertia about its own mass centre, P axes [kg m²]
            for j, (kind, n_steps) in zip(JOINTS, structure.joints[k]):
                # profile: (a0, rate, amp, freq, phase, t1, d1, ...); drive: (max_rate, max_acc, gain, tau)
                add(f"{j}{k}", 5 + 2 * n_steps if kind == "p" else 4)
            if structure.n_modes(k):
                add(f"rho{k}", 3)  # array mass centre from O, B axes [m]
                # per mode: Φ̄ (3), Ĥ (3), M, K, C, ∂J/∂η (xx, yy, zz, xy, xz, yz) (P axes)
                add(f"modes{k}", 15 * structure.n_modes(k))
        if structure.modes:
            add("mtot", 1)  # total mass [kg]: the hub's recoil when the arrays bend
        if structure.orbit:
            add("orbit", orbit_size(structure.orbit_kind))  # model.orbit.orbit_params
        for name in structure.torques:
            if TORQUES[name].n_par:
                add(name, TORQUES[name].n_par)  # the kind's own numbers (TorqueKind.params)
        if structure.sun:
            add("sun", 3)  # unit vector to the sun, N components
        if structure.surfaces:
            # r_O, then each appendage's mass centre (body coordinates) [m], then the on flags of
            # the vehicles' plates at each port (attachments -2 - j: model/surfaces.vehicle_places)
            places = 1 + max([-2 - int(q[0]) for q in structure.surfaces if q[0] <= -2], default=-1)
            add("surf_O", 3 + 3 * structure.n_app + places)
        if structure.eclipse:
            add("shadow", 1)  # Earth-sun distance [m] (the conical shadow's sun disc)
        if structure.cmg is not None:
            add("cmg", CmgModel(*structure.cmg).n_par)  # head (limits, steering), then geometry
        self.size = n

    def __getitem__(self, name) -> slice:
        return self.slices[name]
