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
    """Turns states into output rows (compiled outputs + the loop's held values) and streams them.

    Every value is placed in its CSV column by name: the compiled outputs by the system's
    ``out_layout``, the state's gimbal angles by the cluster's gimbal names, and the loop's held
    values by :attr:`held_columns` (the order in which the closed loop hands them over).

    Parameters
    ----------
    scene : Scene
    system : System  The compiled system of the run.
    p : ndarray  The parameter vector of the scene.
    sink : object with ``write(rows)`` or None  Receives every batch of rows as it is made.
    """

    def __init__(self, scene, system, p, sink):
        self.form = system.formulation
        self.nx = self.form.nx
        self.n_out = system.n_out
        self.out = FastCall.of(system.funcs["out_map"])
        self.out.args[2][:] = p
        self.columns = trajectory_columns(scene)
        self.scene = scene
        self.sink = sink
        self.rows: list[np.ndarray] = []
        col = {c: i for i, c in enumerate(self.columns)}
        names = scene.appendage_names
        cmg = self.form.model.cmg
        gimbals = [] if cmg is None else cmg.gimbal_names
        # compiled output group -> its columns (the track errors are reported in degrees)
        targets = {"omega_BN_B": ["wx", "wy", "wz"], "H_O_N": ["HNx", "HNy", "HNz"], "T": ["T"],
                   "h_B": ["hx", "hy", "hz"], "cmg_singularity": ["cmg_singularity"], "U_strain": ["U_strain"]}
        for k, n in enumerate(names):
            targets[f"alpha{k}"], targets[f"beta{k}"] = [f"alpha_{n}"], [f"beta_{n}"]
            targets[f"track_err{k}"] = [f"track_err_deg_{n}"]
        modes = [f"{a.name}_{m + 1}" for a in scene.appendage for m in range(len(a.mode))]
        targets["eta"] = [f"eta_{m}" for m in modes]
        targets["etadot"] = [f"etadot_{m}" for m in modes]
        #: (column indices, slice of the compiled output, in degrees?) per compiled group
        self.plan = [
            (np.array([col[c] for c in targets[name]]), sl, name.startswith("track_err"))
            for name, sl in system.out_layout.items()
        ]
        self.q_cols = np.array([col[c] for c in ("qw", "qx", "qy", "qz")])
        self.gimbal_cols = np.array([col[g] for g in gimbals], dtype=int)
        #: the loop's held values per row, in the order the closed loop hands them over
        self.held_columns = []
        if cmg is not None:
            self.held_columns += [f"{g}_rate" for g in gimbals] + ["cmg_saturated"]
        if scene.controller is not None:
            self.held_columns += ["tau_cmd_x", "tau_cmd_y", "tau_cmd_z", "att_err_deg"]
        self.held_cols = np.array([col[c] for c in self.held_columns], dtype=int)

    def make(self, ts, xs, held=None) -> np.ndarray:
        """Rows for times ``ts`` and states ``xs``.

        Parameters
        ----------
        ts : array_like, shape (k,)  Times [s].
        xs : array_like, shape (k, nx)  States of the formulation.
        held : array_like, shape (k, len(held_columns)), optional
            The loop's values per row (:attr:`held_columns`); zeros when None (open loop).

        Returns
        -------
        ndarray, shape (k, len(columns))
        """
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
        rows = np.zeros((len(ts), len(self.columns)))
        rows[:, 0] = ts
        rows[:, self.q_cols] = xs[:, :4] / np.linalg.norm(xs[:, :4], axis=1, keepdims=True)
        for cols, sl, degrees in self.plan:
            rows[:, cols] = np.rad2deg(comp[:, sl]) if degrees else comp[:, sl]
        rows[:, self.gimbal_cols] = xs[:, 7 : 7 + len(self.gimbal_cols)]
        if held is not None and len(self.held_cols):
            rows[:, self.held_cols] = np.asarray(held, dtype=float).reshape(len(ts), -1)
        return rows

    def emit(self, rows: np.ndarray) -> None:
        """Keep ``rows`` (k, len(columns)) and hand them to the sink."""
        if len(rows):
            self.rows.append(rows)
            if self.sink is not None:
                self.sink.write(rows)

    def trajectory(self, meta) -> Trajectory:
        """The rows kept so far as a :class:`Trajectory` with ``meta``."""
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
