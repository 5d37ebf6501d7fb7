"""External torques on the station: one class per kind, one registry (:data:`TORQUES`).

A scene's external torque on the body, B components [N m], is

``L_B(t) = u[0:3] + Σ_kinds torque_B(t, q_BN, I_O_B, p)``

* the *held* part ``u[0:3]``, piecewise constant: the run loop sets it for each smooth segment
  (:func:`held_torque_B` at the segment's mid time) and cuts the run at the kinds'
  :func:`torque_breakpoints` (the edges of the ``constant`` windows), so no integrator step
  straddles a jump;
* the *symbolic* part, casadi expressions built into the compiled equations for every kind the
  scene's :class:`~stationbed.model.structure.Structure` names (gravity gradient, orbital
  harmonics). Their numbers enter through the parameter vector ``p``: each kind's own slice,
  named by the kind (:class:`~stationbed.model.structure.ParamLayout`), plus the orbit's.

A kind is found by the name the scene gives it: ``[[torque]] kind = "..."``, or, for gravity
gradient, ``[orbit] gravity_gradient = true``. Adding a kind is one :class:`TorqueKind` subclass
here, added to :data:`TORQUES`, and (for a ``[[torque]]`` kind) its scene model in
:mod:`stationbed.scene` (a member of ``Torque``). The registry's order is the order of the terms
in the equations, of the kinds' slices in ``p`` and of their flags in ``Structure.key``.
"""

from __future__ import annotations

from typing import Any, ClassVar, NamedTuple

import casadi as ca
import numpy as np

from ..core.rotation import dcm
from ..scene import AeroTorque, ConstantTorque, HarmonicTorque, SrpTorque
from .atmosphere import EXPONENTIAL_TABLE, OMEGA_EARTH_RAD_S, band_table, density_symbolic, msis_table
from .environment import gravity_gradient_torque
from .orbit import OrbitAt
from .sun import P_SUN_1AU_N_M2, AU_M, sun_distance_m
from .surfaces import aero_torque_B, srp_torque_B

__all__ = [
    "TorqueKind",
    "ConstantWindow",
    "GravityGradient",
    "OrbitalHarmonic",
    "Environment",
    "Aero",
    "Srp",
    "TORQUES",
    "get_torque",
    "held_torque_B",
    "torque_breakpoints",
]


class Environment(NamedTuple):
    """What a kind with ``needs_env`` gets besides the orbit (casadi expressions at t)."""

    #: the arrays at t (:class:`~stationbed.model.station.ArrayState`: ``C_PB``, angles, ...)
    arrays: Any
    #: unit vector to the sun, N components (3-vector), or None without a [sun] table
    sun_N: Any
    #: fraction of the sun's disc seen, ν in [0, 1] (1 without an eclipse model)
    shadow: Any
    #: DCM from N to B at t (3, 3), shared by the kinds
    C_BN: Any
    #: the plates at t, B axes (:class:`~stationbed.model.surfaces.Plate`), from ``Structure.surfaces``
    plates: Any


class TorqueKind:
    """Base class of an external-torque kind (stateless: class data and class methods).

    The public methods check and call the private ones a kind writes. Rules for implementers:

    1. Set ``kind``, the scene's name for it (the :data:`TORQUES` key). A kind written in the
       scene's ``[[torque]]`` list finds its tables there by that name (:meth:`entries`) and sets
       ``scene_model`` to their pydantic model; a kind named elsewhere writes ``_present(scene)``.
    2. Held part (``held = True``): write ``_held_B(entry, t)``, the torque of one scene entry at
       time ``t`` (ndarray shape (3,), B components [N m]) or None while it is inactive, and
       ``_breakpoints(entry)``, the times where it may jump. It must be constant between them.
    3. Symbolic part (``symbolic = True``): write ``_terms_B(t, q_BN, I_O_B, p_k, orbit)``, the
       torque as a list of casadi 3-vectors (B components [N m]) that the model adds one by one
       to the running sum, in order (the order is part of the generated code). Set
       ``needs_orbit`` when it reads ``orbit`` (an :class:`OrbitAt`); set ``key_tag`` (one
       letter of ``Structure.key``). With ``n_par > 0`` numbers in ``p``, write
       ``_params(scene)`` (shape (n_par,)); the kind reads them back as ``p_k``.
    4. A conservative kind (the torque is minus the attitude gradient of a potential) sets
       ``conservative = True`` and writes ``_potential_J(C_BN, I_O_B, orbit)``: the energy-based
       form (``hamel``) takes it from the potential V and leaves it out of the torque.
    5. Set ``key_always`` only for the kinds the key has always named (``g``, ``h``): their flag
       is written present or not, which keeps the cached libraries' names; a newer kind writes
       its tag only when present.
    6. A kind that needs the arrays' orientation or the sun (surfaces that turn with ``C_PB``)
       sets ``needs_env``: then ``_terms_B`` takes a sixth argument, an :class:`Environment`
       (the arrays at t, the sun, the shadow fraction, the plates' attachments). Torques are
       about the composite mass centre O, which is fixed in B (arrays are balanced about their
       joint axes): a point of the body or of an array lies at ``r - r_O`` in B. The plates'
       geometry is part of the structure (``Structure.surfaces``, folded into the generated code
       as constants, so zero components cost nothing); ``r_O`` and the arrays' mass centres are
       parameters (slice ``surf_O``), so dispersed mass properties keep one compiled system.
    7. Set ``output`` (a CSV column stem, e.g. ``"tau_aero"``) to report the kind's torque per
       row as ``<output>_x, _y, _z``.
    """

    kind: ClassVar[str] = ""
    #: the scene's pydantic model of one ``[[torque]]`` entry of this kind (None: not a list entry)
    scene_model: ClassVar[type | None] = None
    held: ClassVar[bool] = False
    symbolic: ClassVar[bool] = False
    needs_orbit: ClassVar[bool] = False
    conservative: ClassVar[bool] = False
    n_par: ClassVar[int] = 0
    key_tag: ClassVar[str] = ""
    key_always: ClassVar[bool] = False
    needs_env: ClassVar[bool] = False
    output: ClassVar[str] = ""

    # -- the scene ---------------------------------------------------------------------
    @classmethod
    def entries(cls, scene) -> list:
        """The scene's ``[[torque]]`` tables of this kind, in file order."""
        return [t for t in scene.torque if t.kind == cls.kind]

    @classmethod
    def present(cls, scene) -> bool:
        """Whether ``scene`` has this kind."""
        return bool(cls._present(scene))

    @classmethod
    def _present(cls, scene) -> bool:
        return bool(cls.entries(scene))

    @classmethod
    def key(cls, present: bool) -> str:
        """This kind's part of ``Structure.key`` (see rule 5)."""
        if cls.key_always:
            return f"{cls.key_tag}{int(present)}"
        return cls.key_tag if present else ""

    # -- held part ---------------------------------------------------------------------
    @classmethod
    def held_B(cls, entry, t: float) -> np.ndarray | None:
        """Held torque of one scene entry.

        Parameters
        ----------
        entry : pydantic model  One ``[[torque]]`` table of this kind.
        t : float  Time [s] (the segment's mid time).

        Returns
        -------
        ndarray, shape (3,) or None  B components [N m]; None while inactive (or for a kind
        without a held part).
        """
        if not cls.held:
            return None
        out = cls._held_B(entry, t)
        if out is not None and np.shape(out) != (3,):
            raise ValueError(f"torque kind {cls.kind!r}: _held_B returned shape {np.shape(out)}, expected (3,)")
        return out

    @classmethod
    def breakpoints(cls, entry) -> list[float]:
        """Times [s] where the held torque of ``entry`` may jump (empty for a symbolic kind)."""
        return [float(b) for b in cls._breakpoints(entry)] if cls.held else []

    # -- numbers -----------------------------------------------------------------------
    @classmethod
    def params(cls, scene) -> np.ndarray:
        """This kind's numbers in ``p``.

        Parameters
        ----------
        scene : stationbed.scene.Scene

        Returns
        -------
        ndarray, shape (n_par,)
        """
        out = np.asarray(cls._params(scene), dtype=float) if cls.n_par else np.zeros(0)
        if out.shape != (cls.n_par,):
            raise ValueError(f"torque kind {cls.kind!r}: _params returned shape {out.shape}, expected ({cls.n_par},)")
        return out

    # -- symbols -----------------------------------------------------------------------
    @classmethod
    def terms_B(cls, t, q_BN, I_O_B, p_k, orbit: OrbitAt | None, env: Environment | None = None) -> list:
        """The symbolic torque as terms to add in order, each B components [N m] (casadi (3, 1)).

        Parameters
        ----------
        t : casadi SX  Time [s].
        q_BN : casadi SX, shape (4, 1)  Euler parameters of B relative to N (scalar first).
        I_O_B : casadi SX, shape (3, 3)  Total inertia about O, B axes [kg m²].
        p_k : casadi SX, shape (n_par, 1) or None  This kind's slice of ``p``.
        orbit : OrbitAt or None  The orbit at t (None without an orbit).
        env : Environment or None  For a kind with ``needs_env`` (rule 6).
        """
        if not cls.symbolic:
            return []
        if cls.needs_orbit and orbit is None:
            raise ValueError(f"torque kind {cls.kind!r} needs an orbit")
        if not cls.needs_env:
            return list(cls._terms_B(t, q_BN, I_O_B, p_k, orbit))
        if env is None:
            raise ValueError(f"torque kind {cls.kind!r} needs the environment (arrays, sun)")
        return list(cls._terms_B(t, q_BN, I_O_B, p_k, orbit, env))

    @classmethod
    def torque_B(cls, t, q_BN, I_O_B, p_k, orbit: OrbitAt | None, env: Environment | None = None):
        """The symbolic torque, B components [N m]: the sum of :meth:`terms_B` (casadi (3, 1))."""
        total = ca.SX.zeros(3)
        for term in cls.terms_B(t, q_BN, I_O_B, p_k, orbit, env):
            total = total + term
        return total

    @classmethod
    def potential_J(cls, C_BN, I_O_B, orbit: OrbitAt | None):
        """Potential energy of a conservative kind [J] (casadi scalar).

        Parameters
        ----------
        C_BN : casadi SX, shape (3, 3)  DCM from N to B.
        I_O_B : casadi SX, shape (3, 3)  Total inertia about O, B axes [kg m²].
        orbit : OrbitAt or None  The orbit at t.
        """
        if not cls.conservative:
            raise ValueError(f"torque kind {cls.kind!r} has no potential")
        return cls._potential_J(C_BN, I_O_B, orbit)

    # -- plug-in -----------------------------------------------------------------------
    @classmethod
    def _held_B(cls, entry, t):  # pragma: no cover - abstract
        raise NotImplementedError

    @classmethod
    def _breakpoints(cls, entry):  # pragma: no cover - abstract
        raise NotImplementedError

    @classmethod
    def _params(cls, scene):  # pragma: no cover - abstract
        raise NotImplementedError

    @classmethod
    def _terms_B(cls, t, q_BN, I_O_B, p_k, orbit):  # pragma: no cover - abstract
        raise NotImplementedError

    @classmethod
    def _potential_J(cls, C_BN, I_O_B, orbit):  # pragma: no cover - abstract
        raise NotImplementedError


class ConstantWindow(TorqueKind):
    """``kind = "constant"``: ``torque_B`` [N m] (B components) on ``start <= t < stop`` [s].

    Held: the run is cut at ``start`` and ``stop``, the torque is constant in between.
    """

    kind = "constant"
    scene_model = ConstantTorque
    held = True

    @classmethod
    def _held_B(cls, entry, t):
        return np.array(entry.torque_B) if entry.start <= t < entry.stop else None

    @classmethod
    def _breakpoints(cls, entry):
        return [entry.start, entry.stop]


class GravityGradient(TorqueKind):
    """``[orbit] gravity_gradient = true``: a point-mass Earth's gravity gradient,
    ``L_gg = 3 μ/r³ R̂_B × (I_O_B R̂_B)`` (:func:`~stationbed.model.environment.gravity_gradient_torque`),
    ``R̂_B = C_BN R̂_N`` with the orbit's actual position (``R̂_N = (cos u, sin u cos i, sin u sin i)``
    and ``μ/r³ = n²`` on a circular orbit).

    Conservative: ``V = (3/2) μ/r³ R̂_Bᵀ I_O_B R̂_B`` (Quinn Eq. 27-28, constants dropped). On a
    non-circular orbit V depends on t as well; the Hamel form only takes its attitude gradient at
    fixed t, which is the torque, so the forms still agree (the energy T + V is then not conserved).
    """

    kind = "gravity_gradient"
    symbolic = True
    needs_orbit = True
    conservative = True
    key_tag = "g"
    key_always = True
    output = "tau_gg"  # per row, B components [N m] (the disturbance panel of ``stationbed plot``)

    @classmethod
    def _present(cls, scene) -> bool:
        return scene.orbit is not None and scene.orbit.gravity_gradient

    @classmethod
    def _terms_B(cls, t, q_BN, I_O_B, p_k, orbit):
        R_hat_B = ca.mtimes(dcm(q_BN), orbit.r_hat_N)
        return [gravity_gradient_torque(R_hat_B, I_O_B, orbit.mu_r3)]

    @classmethod
    def _potential_J(cls, C_BN, I_O_B, orbit):
        R_hat_B = ca.mtimes(C_BN, orbit.r_hat_N)
        return 1.5 * orbit.mu_r3 * ca.dot(R_hat_B, ca.mtimes(I_O_B, R_hat_B))


class OrbitalHarmonic(TorqueKind):
    """``kind = "orbital_harmonic"``: ``bias + Σ_k cos_k cos(k u) + sin_k sin(k u)`` (k = 1, 2),
    ``u`` the argument of latitude, B components [N m]; the entries' coefficients are summed.

    ``p_k`` (15): bias, cos1, sin1, cos2, sin2, each B components [N m];
    ``cos 2u = cos²u - sin²u``, ``sin 2u = 2 sin u cos u`` (no further trigonometry).
    """

    kind = "orbital_harmonic"
    scene_model = HarmonicTorque
    symbolic = True
    needs_orbit = True
    n_par = 15
    key_tag = "h"
    key_always = True

    @classmethod
    def _params(cls, scene):
        h = np.zeros(15)
        for t in cls.entries(scene):
            h += np.concatenate([t.bias_B, t.cos1_B, t.sin1_B, t.cos2_B, t.sin2_B])
        return h

    @classmethod
    def _terms_B(cls, t, q_BN, I_O_B, p_k, orbit):
        cu, su = orbit.cos_u, orbit.sin_u
        return [
            p_k[0:3],
            p_k[3:6] * cu,
            p_k[6:9] * su,
            p_k[9:12] * (cu * cu - su * su),  # cos 2u
            p_k[12:15] * (2 * su * cu),  # sin 2u
        ]


def v_rel_B(C_BN, orbit: OrbitAt):
    """Velocity of the station relative to an atmosphere co-rotating with the Earth,
    ``C_BN (v_N - ω_E × r_N)``, ω_E along N's z (the Earth's pole), B components [m/s]."""
    r, v = orbit.r_N, orbit.v_N
    v_rel_N = ca.vertcat(v[0] + OMEGA_EARTH_RAD_S * r[1], v[1] - OMEGA_EARTH_RAD_S * r[0], v[2])
    return ca.mtimes(C_BN, v_rel_N)


class Aero(TorqueKind):
    """``kind = "aero"``: free-molecular flat-plate drag on the ``[[surface]]`` plates
    (:func:`~stationbed.model.surfaces.aero_torque_B`), air co-rotating with the Earth
    (:func:`v_rel_B`), density of ``[atmosphere]`` (:mod:`~stationbed.model.atmosphere`).

    ``p_k``: ``density_scale``, then the density bands (3 per band).
    """

    kind = "aero"
    scene_model = AeroTorque
    symbolic = True
    needs_orbit = True
    needs_env = True
    n_par = 1 + band_table().size
    key_tag = "d"
    output = "tau_aero"

    @classmethod
    def _params(cls, scene):
        atm = scene.atmosphere
        scale = 1.0 if atm is None else atm.density_scale
        table = EXPONENTIAL_TABLE
        if atm is not None and atm.model == "msis":
            table = msis_table(scene.sun.epoch, atm.f107, atm.f107a, atm.ap)
        return np.concatenate([[scale], band_table(table)])

    @classmethod
    def _terms_B(cls, t, q_BN, I_O_B, p_k, orbit, env):
        rho = density_symbolic(orbit.r_N, p_k[1:], p_k[0])
        return [aero_torque_B(env.plates, v_rel_B(env.C_BN, orbit), rho)[1]]


class Srp(TorqueKind):
    """``kind = "srp"``: solar radiation pressure on the ``[[surface]]`` plates
    (:func:`~stationbed.model.surfaces.srp_torque_B`), ``P = 4.56e-6 N/m² (AU/d)²`` with the
    epoch's sun distance d (1 AU without an epoch), times the shadow fraction ν.

    ``p_k``: the pressure P [N/m²] at the sun's distance.
    """

    kind = "srp"
    scene_model = SrpTorque
    symbolic = True
    needs_env = True
    n_par = 1
    key_tag = "r"
    output = "tau_srp"

    @classmethod
    def _params(cls, scene):
        pressure = P_SUN_1AU_N_M2 * (AU_M / sun_distance_m(scene.sun)) ** 2
        return np.array([pressure])

    @classmethod
    def _terms_B(cls, t, q_BN, I_O_B, p_k, orbit, env):
        s_B = ca.mtimes(env.C_BN, env.sun_N)
        return [srp_torque_B(env.plates, s_B, p_k[0] * env.shadow)[1]]


#: kind name -> class; the order is the order of the terms, of the slices in p and of the key
TORQUES: dict[str, type[TorqueKind]] = {
    cls.kind: cls for cls in (ConstantWindow, GravityGradient, OrbitalHarmonic, Aero, Srp)
}


def get_torque(kind: str) -> type[TorqueKind]:
    """The :class:`TorqueKind` registered as ``kind``; ValueError listing the valid names."""
    try:
        return TORQUES[kind]
    except (KeyError, TypeError):
        raise ValueError(f"unknown torque kind {kind!r}; valid: {', '.join(TORQUES)}") from None


def held_torque_B(scene, t: float) -> np.ndarray:
    """Sum of the scene's held torques (in its ``[[torque]]`` order).

    Parameters
    ----------
    scene : stationbed.scene.Scene
    t : float  Time [s].

    Returns
    -------
    ndarray, shape (3,)  B components [N m].
    """
    u = np.zeros(3)
    for entry in scene.torque:
        held = get_torque(entry.kind).held_B(entry, t)
        if held is not None:
            u += held
    return u


def torque_breakpoints(scene) -> list[float]:
    """Times [s] where the scene's held torque may jump (unsorted, may repeat, may be ±inf)."""
    return [b for entry in scene.torque for b in get_torque(entry.kind).breakpoints(entry)]
