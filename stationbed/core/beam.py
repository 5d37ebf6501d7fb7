"""Beam shapes: the Quinn Eq. 24 integrals of a uniform Euler–Bernoulli cantilever, and the
participation check of declared modes (pure numpy helpers).

:func:`beam_mode` gives the integrals of a uniform Euler–Bernoulli cantilever (root, span and
deflection directions in P), with the shape normalised to 1 at the tip: ``η_k`` is then the
tip deflection of mode k in metres.
"""

from __future__ import annotations

import functools
import math

import numpy as np

__all__ = ["beam_mode", "beam_inertia_derivative", "BETA_L", "cantilever_shape", "check_participation", "axis_vector"]

#: roots of 1 + cos(βL) cosh(βL) = 0: clamped-free Euler–Bernoulli beam, modes 1..6
BETA_L = (1.8751040687119611, 4.6940911329741745, 7.8547574382376126, 10.995540734875467, 14.137168391046471, 17.278759532088237)

AXES = {"x": 0, "y": 1, "z": 2}


def axis_vector(name: str) -> np.ndarray:
    """Unit vector, P components, of an axis name like ``"y"`` or ``"-z"`` (the scene's ``Beam``)."""
    sign = -1.0 if name.startswith("-") else 1.0
    e = np.zeros(3)
    e[AXES[name.lstrip("+-")]] = sign
    return e


def cantilever_shape(n: int, s: np.ndarray, length: float) -> np.ndarray:
    """Mode ``n`` (1-based) of a uniform clamped-free beam at stations ``s`` in [0, L], tip = 1.

    ``ψ = cosh x - cos x - σ (sinh x - sin x)``, ``x = β s``, evaluated without cancellation:
    ``cosh x - σ sinh x = ((1 - σ) eˣ + (1 + σ) e⁻ˣ) / 2`` with
    ``1 - σ = (sin βL - cos βL - e^(-βL)) / (sinh βL + sin βL)`` (σ → 1 as βL grows, and the
    direct form loses ~cosh βL of precision: 1.6e7 at mode 6)."""
    bl = BETA_L[n - 1]
    den = math.sinh(bl) + math.sin(bl)
    one_m = (math.sin(bl) - math.cos(bl) - math.exp(-bl)) / den  # 1 - σ
    sigma = 1.0 - one_m

    def psi(x):
        return 0.5 * (one_m * np.exp(x) + (1.0 + sigma) * np.exp(-x)) - np.cos(x) + sigma * np.sin(x)

    return psi(bl / length * np.asarray(s, float)) / psi(np.array(bl))


@functools.lru_cache(maxsize=8)
def _gauss_legendre(n: int):
    """Nodes and weights on [-1, 1] (cached: numpy computes them by an eigenvalue problem)."""
    return np.polynomial.legendre.leggauss(n)


def _beam_stations(n: int, length: float, mass: float, root, span: str, deflection: str, n_quad: int):
    """Quadrature of cantilever mode ``n``: ``(dm, ψ, a, e_d)`` at ``n_quad`` Gauss–Legendre stations
    (``a`` the points from the P origin, ``e_d`` the deflection direction; uniform mass per length)."""
    e_s, e_d = axis_vector(span), axis_vector(deflection)
    if abs(e_s @ e_d) > 0.5:
        raise ValueError(f"span {span!r} and deflection {deflection!r} must be different axes")
    xg, wg = _gauss_legendre(n_quad)
    s = 0.5 * length * (xg + 1.0)
    w = 0.5 * length * wg * (mass / length)  # dm at each station
    a = np.asarray(root, float)[None, :] + s[:, None] * e_s[None, :]  # points relative to the P origin
    return w, cantilever_shape(n, s, length), a, e_d


def beam_mode(n: int, length: float, mass: float, root, span: str, deflection: str, n_quad: int = 96):
    """Quinn Eq. 24 integrals ``(Φ̄, Ĥ, M)`` of cantilever mode ``n``, P components about the
    array's mass centre (the P origin). The beam runs from ``root`` along ``span`` and bends
    along ``deflection`` (axis names like ``"y"`` or ``"-z"``); uniform mass per length.
    Gauss–Legendre quadrature with ``n_quad`` points (exact to ~1e-15 for n <= 6)."""
    w, psi, a, e_d = _beam_stations(n, length, mass, root, span, deflection, n_quad)
    phi_bar = float(np.sum(w * psi)) * e_d
    H_hat = np.sum((w * psi)[:, None] * np.cross(a, e_d[None, :]), axis=0)
    M = float(np.sum(w * psi * psi))
    return phi_bar, H_hat, M


def beam_inertia_derivative(n: int, length: float, mass: float, root, span: str, deflection: str, n_quad: int = 96):
    """``∂J/∂η = ∫ (2 a·Φ E - a Φᵀ - Φ aᵀ) dm`` of cantilever mode ``n`` [kg m], shape (3, 3), P
    axes: the first-order change of the array's inertia about its (undeformed) mass centre per unit
    of the modal coordinate. With ``Φ = ψ e_d`` and ``f = ∫ ψ a dm`` it is
    ``2 (f·e_d) E - f e_dᵀ - e_d fᵀ``. Arguments as for :func:`beam_mode`."""
    w, psi, a, e_d = _beam_stations(n, length, mass, root, span, deflection, n_quad)
    f = np.sum((w * psi)[:, None] * a, axis=0)
    return 2.0 * (f @ e_d) * np.eye(3) - np.outer(f, e_d) - np.outer(e_d, f)


def check_participation(mass: float, J: np.ndarray, modes) -> float:
    """Fraction of the array's mass or inertia left, in its worst direction, after its modes'
    effective masses: the smallest eigenvalue of ``S (diag(m E, J) - Σ_k v_k v_kᵀ / M_k) S``,
    ``v_k = [Φ̄_k; Ĥ_k]``, ``S = diag(E/√m, J^-½)`` (1: no mode; 0: the modes take it all).

    Modes of a real structure take at most all of its mass and inertia, so this is >= 0; a
    negative value means the declared participations are not physical (the coupled mass matrix
    would not be positive definite and the motion would be unstable)."""
    evals, evecs = np.linalg.eigh(np.asarray(J, float))
    S = np.zeros((6, 6))
    S[:3, :3] = np.eye(3) / math.sqrt(mass)
    S[3:, 3:] = evecs @ np.diag(evals**-0.5) @ evecs.T
    R = np.eye(6)
    for phi_bar, H_hat, M in modes:
        v = S @ np.concatenate([phi_bar, H_hat])
        R -= np.outer(v, v) / M
    return float(np.linalg.eigvalsh(R).min())
