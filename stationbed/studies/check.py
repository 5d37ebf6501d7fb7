"""Cross-formulation equivalence: run every formulation on a scene and compare (DESIGN §6, §8).

The formulations are mathematically identical (TP-2511 Appendix A, and Ḣ = L - ω × H
expanded), so their trajectories differ only by integration error. With an error-controlled
integrator at relative tolerance ``rtol`` the local error per step is below ``rtol`` of the
state; over the ~10²-10⁴ steps of a shipped scenario the global error stays below 10³ rtol
(measured: the largest mutual attitude difference on the shipped scenarios is 86 rtol, ISS over
3 orbits; see docs/design.md). The tolerances are therefore scaled to rtol:

* attitude: ``CHECK_GAIN * rtol`` rad (principal angle between the two attitudes),
* rate:     ``CHECK_GAIN * rtol * max|ω|`` rad/s,
* momentum: ``CHECK_GAIN * rtol * max(|H|, |h|)`` N m s (H about the composite CM, N components;
  h the CMG cluster's momentum, which sets the scale when a station starts at rest),
* modes (flexible scenes): ``CHECK_GAIN * rtol * max|η|`` on every modal coordinate ``eta_*``,

floored at ``FLOOR`` times the scale for very tight rtol (float64 round-off over a run).
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass

import numpy as np

from ..formulations import FORMULATIONS
from ..core.rotation import rotation_angle
from ..scene import Scene
from ..run.simulation import simulate
from ..run.trajectory import Trajectory

__all__ = ["CheckResult", "check_scene", "compare", "CHECK_GAIN"]

#: Global-error allowance in units of rtol (see module docstring for the reason).
CHECK_GAIN = 1.0e3
#: Round-off floor: float64 over ~10⁵ operations per step and ~10⁴ steps.
FLOOR = 1e-12


@dataclass
class PairDiff:
    """Largest differences of two formulations over a run: attitude angle [rad], rate [rad/s],
    H_O_N [N m s], modal coordinates (flexible scenes)."""
    a: str
    b: str
    att_rad: float
    rate: float
    H: float
    eta: float | None = None  # largest modal-coordinate difference (flexible scenes)


@dataclass
class CheckResult:
    """Pairwise differences of every formulation on one scene, with the tolerances they are held to."""
    scene: str
    rtol: float
    tol_att_rad: float
    tol_rate: float
    tol_H: float
    pairs: list[PairDiff]
    trajectories: dict[str, Trajectory]
    tol_eta: float | None = None
    wall_s: float = 0.0  # the runs of every formulation [s]

    def pair_ok(self, p: PairDiff) -> bool:
        """Whether one pair agrees within every tolerance."""
        ok = p.att_rad <= self.tol_att_rad and p.rate <= self.tol_rate and p.H <= self.tol_H
        return ok and (p.eta is None or p.eta <= self.tol_eta)

    @property
    def ok(self) -> bool:
        """Whether every pair agrees."""
        return all(self.pair_ok(p) for p in self.pairs)

    def table(self) -> str:
        """The differences and tolerances as a text table (what ``stationbed check`` prints)."""
        flex = self.tol_eta is not None
        lines = [
            f"scene {self.scene}: {len(self.trajectories)} formulations at rtol {self.rtol:g}",
            f"{'pair':<26} {'attitude [rad]':>15} {'rate [rad/s]':>14} {'H [N m s]':>12}"
            + (f" {'modes eta':>12}" if flex else "")
            + "  verdict",
        ]
        for p in self.pairs:
            lines.append(
                f"{p.a + ' vs ' + p.b:<26} {p.att_rad:15.3e} {p.rate:14.3e} {p.H:12.3e}"
                + (f" {p.eta:12.3e}" if flex else "")
                + f"  {'ok' if self.pair_ok(p) else 'DISAGREE'}"
            )
        lines.append(
            f"{'tolerance':<26} {self.tol_att_rad:15.3e} {self.tol_rate:14.3e} {self.tol_H:12.3e}"
            + (f" {self.tol_eta:12.3e}" if flex else "")
        )
        return "\n".join(lines)


def compare(a: Trajectory, b: Trajectory) -> tuple[float, float, float]:
    """Largest attitude angle [rad], rate [rad/s] and H_O_N [N m s] differences of two runs."""
    if a.data.shape[0] != b.data.shape[0] or not np.allclose(a.t, b.t):
        raise ValueError("trajectories have different output times")
    att = float(np.max(rotation_angle(a.q_BN, b.q_BN)))
    rate = float(np.max(np.linalg.norm(a.omega_BN_B - b.omega_BN_B, axis=1)))
    H = float(np.max(np.linalg.norm(a.H_O_N - b.H_O_N, axis=1)))
    return att, rate, H


def eta_columns(tr: Trajectory) -> list[str]:
    """The modal-coordinate columns ``eta_*`` of a trajectory (none for a rigid scene)."""
    return [c for c in tr.columns if c.startswith("eta_")]


def compare_modes(a: Trajectory, b: Trajectory) -> float:
    """Largest difference of the modal coordinates ``eta_*`` of two runs (0 if rigid)."""
    cols = eta_columns(a)
    return float(np.max(np.abs(a.cols(*cols) - b.cols(*cols)))) if cols else 0.0


def check_scene(
    scene: Scene, *, rtol: float | None = None, duration: float | None = None, formulations=None, integrator=None
) -> CheckResult:
    """Run every formulation (or ``formulations``) on ``scene`` and compare them pairwise."""
    t0 = time.perf_counter()
    rtol = scene.simulation.rtol if rtol is None else rtol
    forms = list(formulations or FORMULATIONS)
    names = [f if isinstance(f, str) else f.name for f in forms]
    trajs = {
        n: simulate(scene, formulation=f, rtol=rtol, duration=duration, integrator=integrator)
        for n, f in zip(names, forms)
    }
    ref = trajs[names[0]]
    w_scale = float(np.max(np.linalg.norm(ref.omega_BN_B, axis=1)))
    H_scale = float(np.max(np.linalg.norm(ref.H_O_N, axis=1)))
    if "hx" in ref.columns:  # momentum exchange from rest: H_O_N ~ 0, the cluster's h sets the scale
        H_scale = max(H_scale, float(np.max(np.linalg.norm(ref.cols("hx", "hy", "hz"), axis=1))))
    gain = max(CHECK_GAIN * rtol, FLOOR)
    flex = bool(eta_columns(ref))
    pairs = [
        PairDiff(a, b, *compare(trajs[a], trajs[b]), compare_modes(trajs[a], trajs[b]) if flex else None)
        for a, b in itertools.combinations(names, 2)
    ]
    eta_scale = float(np.max(np.abs(ref.cols(*eta_columns(ref))))) if flex else 0.0
    return CheckResult(
        scene=scene.name,
        rtol=rtol,
        tol_att_rad=gain,
        tol_rate=gain * max(w_scale, 1e-12),
        tol_H=gain * max(H_scale, 1e-12),
        pairs=pairs,
        trajectories=trajs,
        tol_eta=gain * max(eta_scale, 1e-12) if flex else None,
        wall_s=time.perf_counter() - t0,
    )
