"""Charts of linear plants and loops: Bode, pole-zero and Nichols (matplotlib, headless Agg)."""

from __future__ import annotations

import numpy as np
from scipy.linalg import eigvals

from ..core.plotting import pyplot, save_png

__all__ = ["pyplot", "siso_zeros", "bode_png", "pole_zero_png", "nichols_png", "AXES"]

AXES = ("x (roll)", "y (pitch)", "z (yaw)")


def structural_part(A, b, c, rel: float = 1e-12) -> np.ndarray:
    """Indices of the states both reachable from ``b`` and seen by ``c`` through the structure of
    ``A`` (entries below ``rel`` of their row's largest are zeros): the rest only adds poles that
    cancel against zeros (gimbal angles behind an exact steering law, decoupled joints)."""
    scale = np.abs(A).max(axis=1, keepdims=True)
    S = np.abs(A) > rel * np.where(scale > 0, scale, 1.0)
    reach = np.abs(b) > rel * np.abs(b).max()
    while True:
        more = reach | S[:, reach].any(axis=1)
        if (more == reach).all():
            break
        reach = more
    seen = np.abs(c) > rel * np.abs(c).max()
    while True:
        more = seen | S[seen].any(axis=0)
        if (more == seen).all():
            break
        seen = more
    return np.nonzero(reach & seen)[0]


def siso_zeros(A, b, c, d=0.0) -> np.ndarray:
    """Finite transmission zeros of ``c (sI - A)⁻¹ b + d`` on its :func:`structural_part`: the
    finite generalised eigenvalues of the Rosenbrock pencil ``[[A, b], [c, d]] - s [[I, 0], [0, 0]]``."""
    k = structural_part(A, b, c)
    A, b, c = A[np.ix_(k, k)], b[k], c[k]
    n = A.shape[0]
    M = np.block([[A, b.reshape(n, 1)], [c.reshape(1, n), np.array([[d]])]])
    N = np.zeros((n + 1, n + 1))
    N[:n, :n] = np.eye(n)
    z = eigvals(M, N)
    return z[np.isfinite(z) & (np.abs(z) < 1e12)]


def _freq(A, lo=None, hi=None):
    lam = np.abs(np.linalg.eigvals(A))
    lam = lam[lam > 1e-9]
    lo = lo or (lam.min() / 30 if lam.size else 1e-5)
    hi = hi or (lam.max() * 30 if lam.size else 10.0)
    return np.logspace(np.log10(lo), np.log10(hi), 5000)


def _response(A, b, c, w):
    n = A.shape[0]
    return np.array([c @ np.linalg.solve(1j * wk * np.eye(n) - A, b) for wk in w])


def bode_png(path, sys, pairs, title: str, units: str) -> None:
    """Bode magnitude and phase of the SISO channels ``pairs`` [(input index, output index,
    label)] of a continuous ``control.StateSpace``."""
    plt = pyplot()
    A, B, C = sys.A, sys.B, sys.C
    w = _freq(A)
    fig, (am, ap) = plt.subplots(2, 1, figsize=(9, 7), sharex=True)
    for i, o, label in pairs:
        G = _response(A, B[:, i], C[o], w)
        am.loglog(w, np.abs(G), label=label)
        ap.semilogx(w, np.degrees(np.unwrap(np.angle(G))), label=label)
    _finish_bode(plt, fig, (am, ap), path, title, (f"magnitude [{units}]", "phase [deg]"))


def pole_zero_png(path, poles, zeros: dict, title: str, modal_poles=()) -> None:
    """Poles (x) and per-channel zeros (o) in the s-plane: the whole plane, and the low-frequency
    region where the attitude poles sit (1.5 x the largest |pole| that is not an array mode)."""
    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(12, 5.2))
    rest = [p for p in poles if not any(abs(p - m) < 1e-12 * max(1.0, abs(m)) for m in modal_poles)]
    zoom = float(f"{1.5 * max((abs(p) for p in rest), default=0.01) or 0.01:.1g}")
    for ax, lim in zip(axes, (None, zoom)):
        ax.axhline(0, color="0.6", lw=0.8)
        ax.axvline(0, color="0.6", lw=0.8)
        p = np.asarray(poles)
        sel = np.ones(p.size, bool) if lim is None else np.abs(p) < lim
        ax.plot(p[sel].real, p[sel].imag, "x", ms=9, mew=2, color="k", label="poles")
        mp = np.asarray(modal_poles)
        if mp.size:
            msel = np.ones(mp.size, bool) if lim is None else np.abs(mp) < lim
            ax.plot(mp[msel].real, mp[msel].imag, "x", ms=11, mew=2.5, color="tab:red", label="array-mode poles")
        for k, (label, z) in enumerate(zeros.items()):
            z = np.asarray(z)
            zs = z if lim is None else z[np.abs(z) < lim]
            ax.plot(zs.real, zs.imag, "o", mfc="none", ms=7 + 3 * k, label=f"zeros {label}")
        if lim is not None:
            ax.set_xlim(-lim, lim)
            ax.set_ylim(-lim, lim)
            ax.set_title(f"{title}: |s| < {lim} rad/s")
        else:
            ax.set_title(f"{title}: all")
        ax.set_xlabel("Re s [rad/s]")
        ax.set_ylabel("Im s [rad/s]")
        ax.grid(True, alpha=0.3)
    axes[1].legend(fontsize=8, loc="upper left")
    save_png(plt, fig, path)


def loop_bode_png(path, loops, labels, title: str) -> None:
    """Bode of the loop transfer functions ``L_i`` with the gain crossover marked."""
    plt = pyplot()
    fig, (am, ap) = plt.subplots(2, 1, figsize=(9, 7), sharex=True)
    A0 = loops[0].A
    w = _freq(A0)
    for L, label in zip(loops, labels):
        G = _response(L.A, L.B[:, 0], L.C[0], w) + L.D[0, 0]
        am.semilogx(w, 20 * np.log10(np.abs(G)), label=label)
        ap.semilogx(w, np.degrees(np.unwrap(np.angle(G))), label=label)
    am.axhline(0, color="k", lw=0.8)
    ap.axhline(-180, color="k", lw=0.8)
    _finish_bode(plt, fig, (am, ap), path, title, ("|L(jω)| [dB]", "phase of L [deg]"))


def nichols_png(path, loops, labels, title: str) -> None:
    """Nichols chart of the loops: open-loop gain [dB] against phase [deg], the critical point
    (-180 deg, 0 dB) marked, with python-control's grid of closed-loop gain contours."""
    import control

    plt = pyplot()
    fig, ax = plt.subplots(figsize=(8, 6.5))
    w = _freq(loops[0].A)
    for L, label in zip(loops, labels):
        G = _response(L.A, L.B[:, 0], L.C[0], w) + L.D[0, 0]
        ph = np.degrees(np.unwrap(np.angle(G)))
        ph = ph - 360.0 * np.round((ph[np.argmin(np.abs(np.abs(G) - 1))] + 180.0) / 360.0)  # crossover near -180..180
        ax.plot(ph, 20 * np.log10(np.abs(G)), label=label)
    ax.set_xlim(-360, 0)
    ax.set_ylim(-60, 60)
    control.nichols_grid(ax=ax)
    ax.plot([-180], [0], "r+", ms=14, mew=2, label="critical point")
    ax.set_xlabel("phase of L [deg]")
    ax.set_ylabel("|L| [dB]")
    ax.set_title(title)
    ax.legend(fontsize=8, loc="upper right")
    save_png(plt, fig, path)


def _finish_bode(plt, fig, axes, path, title: str, ylabels) -> None:
    """Label, grid and save a Bode figure (magnitude axis over phase axis)."""
    am, ap = axes
    am.set_ylabel(ylabels[0])
    ap.set_ylabel(ylabels[1])
    ap.set_xlabel("frequency ω [rad/s]")
    am.set_title(title)
    for a in axes:
        a.grid(True, which="both", alpha=0.3)
    am.legend(fontsize=8)
    save_png(plt, fig, path)
