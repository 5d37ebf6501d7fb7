"""Docking and undocking physics (issue 35): pure functions of two rigid bodies, and the state
jump of a capture or a separation. The contract is in docs/design.md "Docking".

Two bodies, the station s (mass m_s, mass centre r_s, everything it carries: arrays, CMGs) and
a vehicle v (m_v, r_v, inertia I_v about its own mass centre), positions in body coordinates
(the origin of ``[body] cm``), B axes. With ``r = r_v - r_s`` and the reduced mass
``μ = m_s m_v / (m_s + m_v)``, the angular momentum of the pair about their common mass centre is

    H = H_s + I_v ω_v + μ r × ṙ          (ṙ the inertial rate of r, B components)

(the two bodies' spins plus the relative orbit's, König's theorem for two bodies). A capture keeps
H: the composite's state gets ``H' = H``; a separation keeps it as well, and the station keeps
``H_s' = H - I_v ω - μ r × (ω × r) - (r_port - r_s) × J`` with J the impulse the spring gives
the vehicle. Both are ``ΔH = K ω + c`` on the state's momentum about its (new) mass centre
(:func:`capture_terms`, :func:`separation_terms`), and :func:`event_jump` applies it on any
formulation's state. The orbit is not touched (docs/design.md bounds what that leaves out).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..core.linalg import inv3
from ..core.massprops import composite_cm, parallel_axis
from ..scene.docking import docked_parts, vehicle_in_B  # (the scene's geometry, re-exported: one definition)

__all__ = ["vehicle_in_B", "docked_parts", "composite", "reduced_mass", "capture_terms", "separation_impulse",
           "separation_terms", "event_jump", "event_terms"]


def composite(masses, cms, inertias):
    """Mass, mass centre and inertia about it (parallel axis) of rigid parts.

    Parameters
    ----------
    masses : sequence of float  [kg]
    cms : sequence of array_like, shape (3,)  Mass centres, body coordinates [m].
    inertias : sequence of array_like, shape (3, 3)  Each about its own mass centre, B axes [kg m²].

    Returns
    -------
    mass [kg], r_O (3,) [m], I_O_B (3, 3) [kg m²]
    """
    r_O = composite_cm(masses, cms)
    I_O = np.zeros((3, 3))
    for m, r, I in zip(masses, cms, inertias):
        I_O = I_O + np.asarray(I, float) + parallel_axis(m, np.asarray(r, float) - r_O)
    return float(np.sum(masses)), r_O, I_O


def reduced_mass(m_s: float, m_v: float) -> float:
    """``μ = m_s m_v / (m_s + m_v)`` [kg]."""
    return m_s * m_v / (m_s + m_v)


def _point_inertia(mu, r):
    return mu * (r @ r * np.eye(3) - np.outer(r, r))


def capture_terms(m_s, r_s, m_v, r_v, I_v_B, rate_VB_B, v_close_B):
    """``ΔH = K ω + c`` of a capture: the vehicle's angular momentum about the composite mass
    centre, for a station turning at ω (B components).

    Parameters
    ----------
    m_s, r_s : station mass [kg] and mass centre [m] before the capture (body coordinates).
    m_v, r_v, I_v_B : the vehicle's mass [kg], mass centre [m], inertia about it, B axes [kg m²].
    rate_VB_B : array_like, shape (3,)  The vehicle's rate relative to B at contact [rad/s].
    v_close_B : array_like, shape (3,)  Its mass centre's velocity relative to the port (the
        station's frame) at contact, B components [m/s].

    Returns
    -------
    K (3, 3) [kg m²], c (3,) [N m s]
        ``K = I_v + μ (|r|² E - r rᵀ)``, ``c = I_v ω_VB + μ r × v_close`` with ``r = r_v - r_s``:
        the vehicle's spin ``I_v (ω + ω_VB)`` plus ``μ r × (ω × r + v_close)``.
    """
    mu = reduced_mass(m_s, m_v)
    r = np.asarray(r_v, float) - np.asarray(r_s, float)
    I_v = np.asarray(I_v_B, float)
    K = I_v + _point_inertia(mu, r)
    c = I_v @ np.asarray(rate_VB_B, float) + mu * np.cross(r, np.asarray(v_close_B, float))
    return K, c


def separation_impulse(m_s, m_v, spring_energy_J=None, delta_v=None) -> float:
    """The impulse [N s] a separation spring gives the vehicle along the port axis: the relative
    speed ``Δv`` (given, or ``sqrt(2 E / μ)`` from the spring's energy E, all of it into the
    relative translation) times the reduced mass."""
    mu = reduced_mass(m_s, m_v)
    if delta_v is None:
        delta_v = 0.0 if spring_energy_J is None else float(np.sqrt(2.0 * spring_energy_J / mu))
    return mu * float(delta_v)


def separation_terms(m_s, r_s, m_v, r_v, I_v_B, r_port, axis_B, impulse_Ns):
    """``ΔH = K ω + c`` of a separation, on the station's momentum about its own mass centre.

    Parameters
    ----------
    m_s, r_s : the station's mass [kg] and mass centre [m] after the separation.
    m_v, r_v, I_v_B : the vehicle leaving (as :func:`capture_terms`).
    r_port, axis_B : the port's position [m] and outward unit axis (B).
    impulse_Ns : float  The spring's impulse on the vehicle along +axis [N s].

    Returns
    -------
    K (3, 3), c (3,)  ``K = -(I_v + μ (|r|² E - r rᵀ))``, ``c = -(r_port - r_s) × J axis``: the
        station keeps the pair's momentum less the vehicle's share, and the spring's reaction
        ``-J axis`` at the port is its angular impulse.
    """
    mu = reduced_mass(m_s, m_v)
    r = np.asarray(r_v, float) - np.asarray(r_s, float)
    K = -(np.asarray(I_v_B, float) + _point_inertia(mu, r))
    arm = np.asarray(r_port, float) - np.asarray(r_s, float)
    c = np.cross(arm, -impulse_Ns * np.asarray(axis_B, float))
    return K, c


def _station_parts(scene):
    """(masses, cms, inertias) of the station's own rigid parts: body and arrays (the arrays'
    inertia about their own mass centres does not enter the jump: it is the same on both sides)."""
    masses = [scene.body.mass] + [a.mass for a in scene.appendage]
    cms = [scene.body.cm] + [a.cm for a in scene.appendage]
    return masses, cms


def event_terms(before, after, event) -> tuple[np.ndarray, np.ndarray]:
    """``(K, c)`` of ``event`` between the configurations ``before`` and ``after`` (scenes):
    the station is everything of the scene but the event's vehicle."""
    ports = {p.name: p for p in before.port}
    vehicle = next(v for v in before.vehicle if v.name == event.vehicle)
    port = ports[event.port or vehicle.port]
    m_v, r_v, I_v, _ = vehicle_in_B(vehicle, port)
    station = after if event.kind == "undock" else before  # the configuration without the vehicle
    masses, cms = _station_parts(station)
    for m, r, _I in docked_parts(station):
        masses.append(m)
        cms.append(r)
    m_s, r_s = float(np.sum(masses)), composite_cm(masses, cms)
    if m_v == 0.0:
        return np.zeros((3, 3)), np.zeros(3)
    axis = np.asarray(port.axis, float)
    if event.kind == "undock":
        J = separation_impulse(m_s, m_v, event.spring_energy_J, event.delta_v)
        return separation_terms(m_s, r_s, m_v, r_v, I_v, port.position, axis, J)
    lateral = np.asarray(event.lateral_velocity_B, float)
    v_close = -event.closing_velocity * axis + (lateral - (lateral @ axis) * axis)
    return capture_terms(m_s, r_s, m_v, r_v, I_v, event.rate_VB_B, v_close)


def event_jump(form, t, x, p_before, p_after, K, c):
    """The state just after an event with ``ΔH = K ω + c`` (casadi, on any formulation's
    state: ``form``), from the state ``x`` just before, at time ``t``.

    The momentum form adds ΔH to its state ``H_O_B``; a rate-state form takes
    ``ω' = ω + I'⁻¹ (ΔH - (I0' - I0) ω)`` (``I' ω' = I ω + ΔH``: the arrays' and the CMGs'
    momentum relative to the body do not change). ``K = 0, c = 0`` with ``p_after = p_before``
    returns ``x`` bit for bit. Rigid arrays only (the scene refuses events with elastic modes).

    Parameters
    ----------
    t : casadi  Time [s].
    x : casadi, shape (nx, 1)  State just before.
    p_before, p_after : casadi, shape (np, 1)  The parameters before and after the event.
    K : casadi, shape (3, 3)  [kg m²];  c : casadi, shape (3, 1)  [N m s]  (:func:`event_terms`).
    """
    model = form.model
    L = model.layout
    omega = form.omega(t, x, p_before)
    dH = ca.mtimes(K, omega) + c
    core = form.state_layout.slice(form.rate_field)
    if form.omega_is_state:
        I_after = model.inertia(t, p_after, form.arrays(t, x, p_after))
        dI0 = ca.reshape(p_after[L["I0"]] - p_before[L["I0"]], 3, 3).T
        new = x[core] + ca.mtimes(inv3(I_after), dH - ca.mtimes(dI0, omega))
    else:
        new = x[core] + dH
    return ca.vertcat(x[0 : core.start], new, x[core.stop :])
