"""The result of a run: named columns over time, CSV/NPZ in and out.

Column contract (DESIGN §6): ``t,qw,qx,qy,qz,wx,wy,wz`` first (q_BN scalar first, omega_BN_B
[rad/s]), then ``HNx,HNy,HNz`` (total angular momentum about the composite mass centre, N
components [N m s]), ``T`` (rotational kinetic energy [J]), then ``alpha_<name>,beta_<name>`` per
appendage [rad], then anything else a scene adds.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["Trajectory", "base_columns", "CORE_COLUMNS"]

CORE_COLUMNS = ["t", "qw", "qx", "qy", "qz", "wx", "wy", "wz", "HNx", "HNy", "HNz", "T"]


def base_columns(appendage_names) -> list[str]:
    cols = list(CORE_COLUMNS)
    for n in appendage_names:
        cols += [f"alpha_{n}", f"beta_{n}"]
    return cols


@dataclass
class Trajectory:
    """A time series table: ``data[:, j]`` is column ``columns[j]``; row i is time ``t[i]``."""

    columns: list[str]
    data: np.ndarray
    meta: dict = field(default_factory=dict)

    def __post_init__(self):
        self.data = np.asarray(self.data, dtype=float).reshape(-1, len(self.columns))
        self._index = {c: j for j, c in enumerate(self.columns)}

    def __len__(self) -> int:
        return self.data.shape[0]

    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self.data[:, self._index[name]]
        except KeyError:
            raise KeyError(f"no column {name!r}; columns: {', '.join(self.columns)}") from None

    def cols(self, *names) -> np.ndarray:
        return self.data[:, [self._index[n] for n in names]]

    @property
    def t(self) -> np.ndarray:
        return self["t"]

    @property
    def q_BN(self) -> np.ndarray:
        return self.cols("qw", "qx", "qy", "qz")

    @property
    def omega_BN_B(self) -> np.ndarray:
        return self.cols("wx", "wy", "wz")

    @property
    def H_O_N(self) -> np.ndarray:
        return self.cols("HNx", "HNy", "HNz")

    # -- files -------------------------------------------------------------------------
    def to_csv(self, path) -> None:
        with open(path, "w", newline="") as fh:
            sink = CsvSink(fh, self.columns)
            sink.write(self.data)

    @classmethod
    def from_csv(cls, path) -> "Trajectory":
        with open(path, newline="") as fh:
            header = next(csv.reader(fh))
            data = np.loadtxt(fh, delimiter=",", ndmin=2)
        return cls(header, data.reshape(-1, len(header)))

    def to_npz(self, path) -> None:
        np.savez_compressed(path, columns=np.array(self.columns), data=self.data)

    @classmethod
    def from_npz(cls, path) -> "Trajectory":
        with np.load(path) as z:
            return cls([str(c) for c in z["columns"]], z["data"])
