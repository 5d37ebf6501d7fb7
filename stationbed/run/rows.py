"""Output rows: the CSV columns of a scene, states turned into rows (compiled outputs plus the
loop's held values), streamed to a sink as they are computed."""

from __future__ import annotations

import numpy as np

from ..core.compile import FastCall
from ..integrators import IntegrationError
from ..model.cmg import CmgModel
from ..scene import Scene
from .system import OUT_CHUNK
from .trajectory import Trajectory, base_columns

__all__ = ["trajectory_columns", "Rows", "check_rows"]


def trajectory_columns(scene: Scene) -> list[str]:
    """The CSV columns of a run of ``scene`` (DESIGN §6 core, then CMG, controller, sun)."""
    cols = base_columns(scene.appendage_names)
    if scene.cmg is not None:
        cmg = CmgModel.of(scene.cmg)
        cols += ["hx", "hy", "hz"]
        names = cmg.gimbal_names
        cols += names + [f"{n}_rate" for n in names]
        if cmg.gimballed:
            cols.append("cmg_singularity")
        cols.append("cmg_saturated")
    if scene.controller is not None:
        cols += ["tau_cmd_x", "tau_cmd_y", "tau_cmd_z", "att_err_deg"]
    if scene.sun is not None:
        cols += [f"track_err_deg_{n}" for n in scene.appendage_names]
    modes = [(a.name, k + 1) for a in scene.appendage for k in range(len(a.mode))]
    if modes:
        cols += [f"eta_{n}_{k}" for n, k in modes] + [f"etadot_{n}_{k}" for n, k in modes] + ["U_strain"]
    return cols


class Rows:
    """Turns states into output rows (compiled outputs + the loop's held values) and streams them."""

    def __init__(self, scene, system, p, sink):
        f = system.funcs
        self.form = system.formulation
        self.nx = self.form.nx
        self.n_out = system.n_out
        self.out = FastCall.of(f["out_map"])
        self.out.args[2][:] = p
        self.columns = trajectory_columns(scene)
        self.scene = scene
        self.sink = sink
        self.rows: list[np.ndarray] = []
        n_app = len(scene.appendage)
        cmg = self.form.model.cmg
        self.ng = 0 if cmg is None else cmg.n_gimbals
        self.has_cmg = cmg is not None
        # compiled output layout: w(3) HN(3) T(1) angles(2 n_app) [h(3) [m]] [track errs]
        self.k_h = 7 + 2 * n_app
        self.k_m = self.k_h + 3
        self.gimbaled = cmg is not None and cmg.gimballed
        self.k_track = self.k_m + (1 if self.gimbaled else 0) if cmg is not None else 7 + 2 * n_app
        self.has_sun = scene.sun is not None
        self.has_ctrl = scene.controller is not None
        # modal outputs (eta, etadot, U_strain) close the compiled row
        self.n_flex = 2 * self.form.model.n_modes + 1 if self.form.model.n_modes else 0

    def make(self, ts, xs, held=None) -> np.ndarray:
        """Rows for times ``ts`` and states ``xs``; ``held`` (k, m) are the loop's values per row:
        gimbal rates, cmg_saturated, tau_cmd(3), att_err_deg (those that apply)."""
        ts = np.asarray(ts, dtype=float)
        xs = np.asarray(xs, dtype=float).reshape(len(ts), self.nx)
        comp = np.empty((len(ts), self.n_out))
        o = self.out
        for k in range(0, len(ts), OUT_CHUNK):
            n = min(OUT_CHUNK, len(ts) - k)
            o.args[0][:n] = ts[k : k + n]
            o.args[1].reshape(OUT_CHUNK, self.nx)[:n] = xs[k : k + n]
            o()
            comp[k : k + n] = o.res[0].reshape(OUT_CHUNK, self.n_out)[:n]
        parts = [ts[:, None], xs[:, :4] / np.linalg.norm(xs[:, :4], axis=1, keepdims=True), comp[:, : self.k_h]]
        held = np.zeros((len(ts), 0)) if held is None else np.asarray(held, dtype=float).reshape(len(ts), -1)
        j = 0
        if self.has_cmg:
            parts.append(comp[:, self.k_h : self.k_h + 3])
            parts.append(xs[:, 7 : 7 + self.ng])
            rates = held[:, j : j + self.ng] if held.shape[1] else np.zeros((len(ts), self.ng))
            parts.append(rates)
            if self.gimbaled:
                parts.append(comp[:, self.k_m : self.k_m + 1])
            parts.append(held[:, j + self.ng : j + self.ng + 1] if held.shape[1] else np.zeros((len(ts), 1)))
            j += self.ng + 1
        if self.has_ctrl:
            parts.append(held[:, j : j + 4])
            j += 4
        if self.has_sun:
            parts.append(np.rad2deg(comp[:, self.k_track : self.n_out - self.n_flex]))
        if self.n_flex:
            parts.append(comp[:, self.n_out - self.n_flex :])
        return np.hstack(parts)

    def emit(self, rows: np.ndarray) -> None:
        if len(rows):
            self.rows.append(rows)
            if self.sink is not None:
                self.sink.write(rows)

    def trajectory(self, meta) -> Trajectory:
        data = np.vstack(self.rows) if self.rows else np.zeros((0, len(self.columns)))
        return Trajectory(self.columns, data, meta)


def check_rows(rows: np.ndarray, emit) -> None:
    """Emit the finite rows; raise at the first non-finite one."""
    bad = ~np.all(np.isfinite(rows), axis=1)
    if bad.any():
        i = int(np.argmax(bad))
        emit(rows[:i])
        raise IntegrationError(rows[i, 0], "outputs are not finite (NaN or inf)")
    emit(rows)
