"""What a scene's equations contain (:class:`Structure`) and the parameter vector's layout.

Two scenes with equal structure share compiled code; their numbers differ only in the parameter
vector ``p``, whose names and slices :class:`ParamLayout` declares once.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..scene import HarmonicTorque

__all__ = ["Structure", "ParamLayout", "JOINTS"]


@dataclass(frozen=True)
class Structure:
    """What a scene's equations contain; two scenes with equal structure share compiled code.

    ``joints`` has per appendage ``((kind, n_steps) for alpha, (kind, n_steps) for beta)`` with
    kind ``"p"`` (profile with ``n_steps`` rate steps) or ``"s"`` (sun-tracking drive, a state).
    ``cmg`` is ``(kind, n_units, steering)`` or None.
    """

    n_app: int
    orbit: bool
    gravity_gradient: bool
    harmonic: bool
    joints: tuple = ()
    sun: bool = False
    cmg: tuple | None = None
    #: elastic modes per appendage (all 0: a rigid scene, whose equations and key do not change)
    modes: tuple = ()

    @classmethod
    def of(cls, scene) -> "Structure":
        def joint(j):
            return ("s", 0) if j.tracked else ("p", len(j.rate_step))

        c = scene.cmg
        return cls(
            n_app=len(scene.appendage),
            orbit=scene.orbit is not None,
            gravity_gradient=scene.orbit is not None and scene.orbit.gravity_gradient,
            harmonic=any(isinstance(t, HarmonicTorque) for t in scene.torque),
            joints=tuple((joint(a.alpha), joint(a.beta)) for a in scene.appendage),
            sun=scene.sun is not None,
            cmg=None if c is None else (c.kind, c.n_units, c.steering if c.kind != "ideal" else "none"),
            modes=tuple(len(a.mode) for a in scene.appendage) if any(a.mode for a in scene.appendage) else (),
        )

    @property
    def key(self) -> str:
        j = "".join(f"{k}{n}" for a in self.joints for k, n in a)
        c = "" if self.cmg is None else f"c{self.cmg[0]}{self.cmg[1]}{self.cmg[2]}"
        f = "" if not self.modes else "f" + "_".join(str(n) for n in self.modes)
        return (
            f"a{self.n_app}o{int(self.orbit)}g{int(self.gravity_gradient)}h{int(self.harmonic)}"
            f"j{j}s{int(self.sun)}{c}{f}"
        )

    def n_modes(self, k: int) -> int:
        return self.modes[k] if self.modes else 0


JOINTS = ("alpha", "beta")


class ParamLayout:
    """Names and slices of the parameter vector ``p`` (declared once, owns the indices)."""

    def __init__(self, structure: Structure, cmg_n_par: int = 0):
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
                add(f"modes{k}", 9 * structure.n_modes(k))  # per mode: Φ̄ (3), Ĥ (3), M, K, C (P axes)
        if structure.modes:
            add("mtot", 1)  # total mass [kg]: the hub's recoil when the arrays bend
        if structure.orbit:
            add("orbit", 6)  # radius [m], inclination [rad], u0 [rad], n [rad/s], cos i, sin i
        if structure.harmonic:
            add("harm", 15)  # bias, cos1, sin1, cos2, sin2 (B, N m), summed over torques
        if structure.sun:
            add("sun", 3)  # unit vector to the sun, N components
        if structure.cmg is not None:
            add("cmg", cmg_n_par)
        self.size = n

    def __getitem__(self, name) -> slice:
        return self.slices[name]
