"""Rotations and directions as a recording draws them, from the model's one definition of each.

Rerun takes a transform's rotation as the quaternion ``(x, y, z, w)`` of the matrix that maps the
child entity's components into its parent's (DESIGN §3): ``C_NB`` for the station, ``C_BP`` for
an array, ``C_NO`` for LVLH. The orbit position, the LVLH frame and the sun direction come from
:mod:`stationbed.model.environment`, quaternion and matrix algebra from
:mod:`stationbed.core.rotation`; everything here works on many rows at once (time along the last
axis of the model's functions, along the first axis here).
"""

from __future__ import annotations

import numpy as np

from ...core.rotation import dcm, euler_321, quat_from_dcm, quat_mult
from ...model.environment import sun_direction_N
from ...model.orbit import orbit_numeric, orbit_plane

__all__ = [
    "xyzw",
    "xyzw_of_dcm",
    "xyzw_C_BP",
    "xyzw_C_NO",
    "R_N_over_a",
    "euler_321_lvlh",
    "sun_vector_N",
]


def xyzw(q) -> np.ndarray:
    """Rerun's component order ``(x, y, z, w)`` of scalar-first quaternions.

    Parameters
    ----------
    q : array_like, shape (..., 4)
        Quaternions ``(w, x, y, z)``.

    Returns
    -------
    ndarray, shape (..., 4)
        The same quaternions as ``(x, y, z, w)``.
    """
    q = np.asarray(q, dtype=float)
    return q[..., [1, 2, 3, 0]]


def xyzw_of_dcm(C) -> np.ndarray:
    """Rerun quaternion ``(x, y, z, w)`` of the rotation matrix ``C`` (child -> parent).

    ``quat_from_dcm(C_BN)`` is the ``q`` with ``dcm(q) = C_BN``, i.e. whose active rotation is
    ``C_BN.T``; so ``C``'s quaternion is ``quat_from_dcm(C.T)``. (Not scipy's ``Rotation``: its
    import, ~0.3 s, would delay the recording process of ``stationbed run --rrd``.)

    Parameters
    ----------
    C : array_like, shape (3, 3)
        Proper rotation matrix mapping the child's components into the parent's.

    Returns
    -------
    ndarray, shape (4,)
    """
    return xyzw(quat_from_dcm(np.asarray(C, dtype=float).T))


def xyzw_C_BP(alpha, beta) -> np.ndarray:
    """Quaternions ``(x, y, z, w)`` of ``C_BP = Ap(alpha, beta).T = Ay(alpha).T Ax(beta).T``.

    ``Ay(a).T`` is the active rotation by ``a`` about y, ``Ax(b).T`` by ``b`` about x, so the
    quaternion is ``q_y(alpha) ⊗ q_x(beta)`` (Hamilton product; checked against ``Ap`` in
    tests/test_rerun.py).

    Parameters
    ----------
    alpha, beta : ndarray, shape (n,)
        Array gimbal angles [rad] (TP-2511 Eq. 35-38).

    Returns
    -------
    ndarray, shape (n, 4)
    """
    ca_, sa = np.cos(0.5 * alpha), np.sin(0.5 * alpha)
    cb, sb = np.cos(0.5 * beta), np.sin(0.5 * beta)
    zero = np.zeros_like(ca_)
    q_y = np.array([ca_, zero, sa, zero])
    q_x = np.array([cb, sb, zero, zero])
    return xyzw(quat_mult(q_y, q_x).T)


def xyzw_C_NO(orbit, t) -> np.ndarray:
    """Quaternions ``(x, y, z, w)`` of ``C_NO = C_ON.T``: ``q_ON`` of the orbit model.

    ``dcm(q_ON) = C_ON`` (:mod:`stationbed.model.orbit`), so ``q_ON`` is the quaternion whose
    active rotation is ``C_NO``, the matrix rerun wants for ``world/lvlh``.

    Parameters
    ----------
    orbit : stationbed.scene.Orbit
    t : ndarray, shape (n,)
        Times since the start of the run [s].

    Returns
    -------
    ndarray, shape (n, 4)
    """
    return xyzw(orbit_numeric(orbit, np.asarray(t, dtype=float)).q_ON.T)


def R_N_over_a(orbit, t) -> np.ndarray:
    """Orbit position over the radius (circular) or semi-major axis (two-body), N components.

    Parameters
    ----------
    orbit : stationbed.scene.Orbit
    t : ndarray, shape (n,)
        Times since the start of the run [s].

    Returns
    -------
    ndarray, shape (n, 3)
        ``r_N / a`` of :func:`stationbed.model.orbit.orbit_numeric` (unit length on a circle).
    """
    return orbit_numeric(orbit, np.asarray(t, dtype=float)).r_N.T / orbit.radius_m


def euler_321_lvlh(q_BN, orbit, t) -> np.ndarray:
    """3-2-1 angles ``(roll, pitch, yaw)`` [rad] of the attitude relative to LVLH.

    ``C_BO = C_BN C_ON.T`` with ``C_BN = dcm(q_BN)`` and ``C_ON`` the orbit model's LVLH, angles
    as :func:`stationbed.core.rotation.euler_321`; all rows at once.

    Parameters
    ----------
    q_BN : ndarray, shape (n, 4)
        Attitude of B relative to N, scalar first.
    orbit : stationbed.scene.Orbit
    t : ndarray, shape (n,)
        Times since the start of the run [s].

    Returns
    -------
    ndarray, shape (n, 3)
    """
    C_BN = dcm(np.asarray(q_BN, dtype=float).T)  # (3, 3, n)
    C_ON = dcm(orbit_numeric(orbit, np.asarray(t, dtype=float)).q_ON)  # (3, 3, n)
    C_BO = np.einsum("ijn,kjn->ikn", C_BN, C_ON)
    return euler_321(C_BO).T


def sun_vector_N(scene) -> np.ndarray:
    """Unit sun direction of ``scene``'s ``[sun]`` table, N components (as the model sees it).

    Parameters
    ----------
    scene : stationbed.scene.Scene
        A scene with a ``[sun]`` table.

    Returns
    -------
    ndarray, shape (3,)
        :func:`stationbed.model.environment.sun_direction_N` at the scene's inclination (0 without
        an orbit).
    """
    return sun_direction_N(scene.sun, *orbit_plane(scene.orbit))
