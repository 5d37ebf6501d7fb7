"""Design models of the LQR laws: a rigid station about an LVLH-fixed attitude, linearised by casadi.

The model (DESIGN §4, stationbed's conventions), written once in casadi SX so its Jacobians are
exact:

* reference frame ``R``, fixed in LVLH (``q_RO``); LVLH turns at ``omega_ON_O = (0, -n, 0)``, so
  ``omega_RN_R = C_RO (0, -n, 0)`` is constant;
* attitude error ``theta = 2 vec(q_BR)`` (3,), with ``q_BR = (sqrt(1 - |theta/2|²), theta/2)``:
  exact for any rotation below 180 deg, ``theta`` ≈ the small rotation angles [rad];
* rate error ``domega = omega_BN_B - C_BR omega_RN_R`` (3,) [rad/s] (the rate of B relative to R);
* rigid body with the plant's inertia ``I_O_B`` (about the composite mass centre, B axes):
  ``I ω̇ = u + L_gg - ω × I ω``, ``L_gg = 3 n² R̂_B × I R̂_B``, ``R̂_B = C_BR C_RO (0, 0, -1)``
  (the zenith; LVLH z is nadir);
* optionally (``cmg=True``) the CMG momentum ``h`` (3,) [N m s] relative to the body with
  ``ḣ = -u - ω × h`` (body-frame derivative; the steering law delivers the body torque ``u``:
  stationbed.model.cmg), and its integral ``z = ∫ h dt`` (3,) [N m s²].

Kinematics: ``θ̇ = q_w δω + (θ/2) × δω`` (from ``q̇_BR = ½ q_BR ⊗ (0, δω)``);
``δω̇ = ω̇ + δω × (C_BR ω_RN_R)`` (from ``Ċ_BR = -[δω×] C_BR``).

The control input ``u`` is the body control torque (B components, N m): what the shipped torque
laws command and what the CMG steering law delivers to the body.
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from stationbed.run.controller import ControllerError
from stationbed.core.rotation import dcm

__all__ = [
    "design_model",
    "linearize",
    "equilibrium_torque",
    "torque_equilibrium_attitude",
    "loop_margins",
    "settling_time",
    "ss_zoh",
    "lvlh_error",
]

#: Largest TEA offset from LVLH the Newton search accepts [rad]: beyond it the "nearest"
#: equilibrium is another principal-axis alignment, not a TEA a station would fly.
TEA_MAX_RAD = math.radians(60.0)
#: Newton's residual at the TEA, ``|ω̇| / n²`` (gravity-gradient terms are ~ΔI/I ~ 0.1-1 in these
#: units): float64 round-off of ~1e-16 relative, with margin.
TEA_RESIDUAL = 1e-10


def design_model(I_O_B, mean_motion: float, *, q_RO=(1.0, 0.0, 0.0, 0.0), gravity_gradient=True, cmg=False):
    """The design model as a casadi Function ``f(x, u) -> x_dot``.

    Parameters
    ----------
    I_O_B : ndarray, shape (3, 3)  Inertia about the composite mass centre, B axes [kg m²].
    mean_motion : float  Orbital rate n [rad/s].
    q_RO : (4,)  Reference attitude relative to LVLH, scalar first.
    gravity_gradient : bool  Include the gravity-gradient torque.
    cmg : bool  Append ``h`` and ``z = ∫ h dt`` to the state (12 states instead of 6).

    Returns
    -------
    casadi.Function  ``f(x, u)``, ``x = [theta, domega(, h, z)]``, ``u`` (3,) [N m].
    """
    J = ca.DM(np.asarray(I_O_B, dtype=float))
    n = float(mean_motion)
    C_RO = dcm(np.asarray(q_RO, dtype=float))
    w_R = ca.DM(C_RO @ np.array([0.0, -n, 0.0]))  # omega_RN_R
    zen_R = ca.DM(C_RO @ np.array([0.0, 0.0, -1.0]))  # R̂ (up), R components
    nx = 12 if cmg else 6
    x = ca.SX.sym("x", nx)
    u = ca.SX.sym("u", 3)
    th, dw = x[0:3], x[3:6]
    e = th / 2
    qw = ca.sqrt(1.0 - ca.dot(e, e))
    C_BR = dcm(ca.vertcat(qw, e))
    w = dw + ca.mtimes(C_BR, w_R)  # omega_BN_B
    th_dot = qw * dw + ca.cross(e, dw)
    L = u - ca.cross(w, ca.mtimes(J, w))
    if gravity_gradient:
        r = ca.mtimes(C_BR, zen_R)
        L = L + 3.0 * n * n * ca.cross(r, ca.mtimes(J, r))
    w_dot = ca.solve(J, L)
    dw_dot = w_dot + ca.cross(dw, ca.mtimes(C_BR, w_R))
    parts = [th_dot, dw_dot]
    if cmg:
        h = x[6:9]
        parts += [-u - ca.cross(w, h), h]
    return ca.Function("design_model", [x, u], [ca.vertcat(*parts)], ["x", "u"], ["x_dot"])


def linearize(f: ca.Function, x0, u0) -> tuple[np.ndarray, np.ndarray]:
    """``A = ∂f/∂x``, ``B = ∂f/∂u`` at ``(x0, u0)`` by casadi AD (``ca.jacobian``)."""
    x = ca.SX.sym("x", f.size1_in(0))
    u = ca.SX.sym("u", f.size1_in(1))
    y = f(x, u)
    jac = ca.Function("jac_design", [x, u], [ca.jacobian(y, x), ca.jacobian(y, u)])
    A, B = jac(np.asarray(x0, float), np.asarray(u0, float))
    return np.array(A), np.array(B)


def equilibrium_torque(f: ca.Function, x0) -> np.ndarray:
    """The constant body torque ``u0`` that makes ``x0`` (at rest relative to R) an equilibrium of
    the attitude dynamics: ``δω̇(x0, u0) = 0`` (the model is affine in ``u``) [N m]."""
    x0 = np.asarray(x0, float)
    _, B = linearize(f, x0, np.zeros(3))
    d = np.array(f(x0, np.zeros(3))).ravel()[3:6]
    return -np.linalg.solve(B[3:6], d)


def torque_equilibrium_attitude(I_O_B, mean_motion: float, gravity_gradient=True) -> np.ndarray:
    """``theta_TEA`` (3,) [rad]: the attitude relative to LVLH, at rest in LVLH with ``h = 0`` and
    no control torque, where gravity gradient balances the gyroscopic torque (Newton from LVLH).

    Without a gravity gradient every LVLH attitude needs a torque unless I is principal there;
    the search is the same.
    """
    f = design_model(I_O_B, mean_motion, gravity_gradient=gravity_gradient)
    th = ca.SX.sym("th", 3)
    res = f(ca.vertcat(th, ca.SX.zeros(3)), ca.SX.zeros(3))[3:6] / max(mean_motion**2, 1e-30)
    G = ca.Function("G", [th], [res, ca.jacobian(res, th)])
    x = np.zeros(3)
    for _ in range(50):
        g, Jg = (np.array(v) for v in G(x))
        step = np.linalg.lstsq(Jg, -g.ravel(), rcond=None)[0]
        # damp steps that would leave the valid range of theta = 2 vec(q)
        s = float(np.linalg.norm(step))
        if s > 0.2:
            step *= 0.2 / s
        x = x + step
        if s < 1e-13:
            break
    g = np.array(G(x)[0]).ravel()
    bad_residual = np.linalg.norm(g) > TEA_RESIDUAL  # dimensionless: ω̇ / n²
    if not np.all(np.isfinite(x)) or bad_residual or np.linalg.norm(x) > TEA_MAX_RAD:
        raise ControllerError(
            f"no torque-equilibrium attitude within {math.degrees(TEA_MAX_RAD):.0f} deg of LVLH for this inertia "
            f"(Newton ended at {np.degrees(x).round(2).tolist()} deg, residual {np.linalg.norm(g):.3g})"
        )
    return x


def ss_zoh(A, B, T: float) -> tuple[np.ndarray, np.ndarray]:
    """Zero-order-hold discretisation over ``T`` [s]: ``(e^{AT}, ∫₀ᵀ e^{As} ds B)``."""
    from scipy.linalg import expm

    n, m = B.shape
    M = np.zeros((n + m, n + m))
    M[:n, :n] = A
    M[:n, n:] = B
    E = expm(M * T)
    return E[:n, :n], E[:n, n:]


def loop_margins(A, B, K) -> list[dict]:
    """Per input channel i: margins of the loop broken at that input, the others closed.

    ``L_i(s) = K_i (sI - A + B_j K_j)⁻¹ B_i`` (j ≠ i), negative feedback. python-control's
    ``stability_margins(..., returnall=True)`` gives every crossing; reported: the smallest upward
    gain margin (> 1; inf when none), the largest downward gain margin (< 1; 0 when none: LQR
    guarantees ≤ 1/2), the smallest phase margin [deg] (LQR guarantees ≥ 60 deg) and the
    stability margin ``min_ω |1 + L(jω)|`` (LQR guarantees ≥ 1: Kalman's return-difference
    inequality), evaluated on a frequency grid.
    """
    import control

    out = []
    m = B.shape[1]
    for i in range(m):
        others = [j for j in range(m) if j != i]
        Ai = A - B[:, others] @ K[others, :]
        L = control.ss(Ai, B[:, [i]], K[[i], :], np.zeros((1, 1)))
        gm, pm, sm, wpc, wgc, wms = control.stability_margins(L, returnall=True)
        gm = np.atleast_1d(np.asarray(gm, float))
        pm = np.atleast_1d(np.asarray(pm, float))
        wgc = np.atleast_1d(np.asarray(wgc, float))
        up = gm[gm > 1.0]
        down = gm[(gm < 1.0) & (gm > 0.0)]
        ok = np.isfinite(pm)
        pm_ok, wgc_ok = np.abs(pm[ok]), wgc[ok] if wgc.size == pm.size else np.full(ok.sum(), math.nan)
        sm = np.atleast_1d(_min_return_difference(Ai, B[:, i], K[i]))
        out.append(
            {
                "gain_margin_up": float(up.min()) if up.size else math.inf,
                "gain_margin_down": float(down.max()) if down.size else 0.0,
                "phase_margin_deg": float(pm_ok.min()) if pm_ok.size else math.inf,
                "crossover_rad_s": float(wgc_ok[np.argmin(pm_ok)]) if pm_ok.size else math.nan,
                "stability_margin": float(sm.min()) if sm.size else math.nan,
            }
        )
    return out


def _min_return_difference(Ai, b, k) -> float:
    """``min_ω |1 + L(jω)|`` on a log grid spanning the loop's poles (python-control's
    ``stability_margins`` reports inf when the minimum is approached only as ω → ∞)."""
    lam = np.abs(np.linalg.eigvals(Ai))
    lam = lam[lam > 0]
    lo, hi = (lam.min(), lam.max()) if lam.size else (1e-6, 1.0)
    w = np.logspace(np.log10(lo) - 3, np.log10(hi) + 3, 3000)
    I = np.eye(Ai.shape[0])
    L = np.array([k @ np.linalg.solve(1j * wk * I - Ai, b) for wk in w])
    return float(np.abs(1.0 + L).min())


def settling_time(poles) -> float:
    """``4 / |Re(slowest pole)|`` [s]: the 2 % settling time of the slowest mode (e⁻⁴ ≈ 1.8 %)."""
    slow = float(np.min(np.abs(np.real(np.asarray(poles)))))
    return math.inf if slow == 0 else 4.0 / slow


def lvlh_error(q_BN, omega_BN_B, q_RN, w_RN_R):
    """``(theta, domega)`` of the design model from a measurement, on floats (runs every tick).

    ``q_BR = conj(q_RN) ⊗ q_BN`` with its scalar part made ≥ 0 (the short way round),
    ``theta = 2 vec(q_BR)`` [rad], ``domega = omega_BN_B - C_BR omega_RN_R`` [rad/s].
    """
    qw, qx, qy, qz = q_BN
    rw, rx, ry, rz = q_RN
    ew = rw * qw + rx * qx + ry * qy + rz * qz
    ex = rw * qx - rx * qw - ry * qz + rz * qy
    ey = rw * qy + rx * qz - ry * qw - rz * qx
    ez = rw * qz - rx * qy + ry * qx - rz * qw
    if ew < 0.0:
        ew, ex, ey, ez = -ew, -ex, -ey, -ez
    vx, vy, vz = w_RN_R
    # C_BR v = v - w t + e × t, t = 2 e × v (controllers/_quat.rotate, inlined)
    tx = 2.0 * (ey * vz - ez * vy)
    ty = 2.0 * (ez * vx - ex * vz)
    tz = 2.0 * (ex * vy - ey * vx)
    wx, wy, wz = omega_BN_B
    return (
        2.0 * ex,
        2.0 * ey,
        2.0 * ez,
        wx - (vx - ew * tx + (ey * tz - ez * ty)),
        wy - (vy - ew * ty + (ez * tx - ex * tz)),
        wz - (vz - ew * tz + (ex * ty - ey * tx)),
    )
