"""The result of a run: named columns over time, CSV/NPZ in and out.

Column contract (DESIGN §6): ``t,qw,qx,qy,qz,wx,wy,wz`` first (q_BN scalar first, omega_BN_B
[rad/s]), then ``HNx,HNy,HNz`` (total angular momentum about the composite mass centre, N
components [N m s]), ``T`` (rotational kinetic energy [J]), then ``alpha_<name>,beta_<name>`` per
appendage [rad], then anything else a scene adds.
"""

from __future__ import annotations

import csv
import warnings
from dataclasses import dataclass, field

import numpy as np

__all__ = ["Trajectory", "base_columns", "CORE_COLUMNS", "CSV_FORMAT"]

#: CSV number format: 17 significant digits, so a float64 reads back bit for bit
CSV_FORMAT = "%.17g"

CORE_COLUMNS = ["t", "qw", "qx", "qy", "qz", "wx", "wy", "wz", "HNx", "HNy", "HNz", "T"]


def base_columns(appendage_names) -> list[str]:
    """The contract columns (DESIGN §6): ``t, q_BN, omega_BN_B, H_O_N, T``, then
    ``alpha_<name>, beta_<name>`` per appendage."""
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
        """The named columns side by side, shape (N, len(names))."""
        return self.data[:, [self._index[n] for n in names]]

    @property
    def t(self) -> np.ndarray:
        """Times [s], shape (N,)."""
        return self["t"]

    @property
    def q_BN(self) -> np.ndarray:
        """Attitude quaternions of B relative to N, scalar first, shape (N, 4)."""
        return self.cols("qw", "qx", "qy", "qz")

    @property
    def omega_BN_B(self) -> np.ndarray:
        """Body rates, B components [rad/s], shape (N, 3)."""
        return self.cols("wx", "wy", "wz")

    @property
    def H_O_N(self) -> np.ndarray:
        """Total angular momentum about the composite mass centre, N components [N m s], shape (N, 3)."""
        return self.cols("HNx", "HNy", "HNz")

    def to_pandas(self):
        """The table as a ``pandas.DataFrame`` indexed by time ``t`` [s] (one column per name; the
        data is copied; ``meta`` goes to ``DataFrame.attrs``). Needs pandas."""
        import pandas as pd

        df = pd.DataFrame(self.data.copy(), columns=list(self.columns))
        df = df.set_index("t") if "t" in self._index else df
        df.attrs.update(self.meta)
        return df

    # -- files -------------------------------------------------------------------------
    def to_csv(self, path) -> None:
        """Write the trajectory as CSV (a header row, then one row per time, full precision)."""
        with open(path, "w", newline="") as fh:
            fh.write(",".join(self.columns) + "\n")
            np.savetxt(fh, np.atleast_2d(self.data), delimiter=",", fmt=CSV_FORMAT)

    @classmethod
    def from_csv(cls, path, *, torn_tail: bool = False) -> "Trajectory":
        """Read a trajectory CSV written by :meth:`to_csv` or ``stationbed run``.

        A header with no rows gives an empty trajectory. A file that is not such a table raises
        ValueError naming the file and the first bad line: empty (no header), a row of another
        width (a file cut mid-row, or damaged), a value that is not a number.

        Parameters
        ----------
        torn_tail : bool
            Read a run's partial rows (``trajectory.partial.csv``) as a process killed mid-write
            (SIGKILL, power loss) leaves them: every line is written with its newline, so a last
            line without one is a torn row, dropped and counted in ``meta["torn_rows"]`` (1,
            else 0), and a header without one is no header (ValueError). Lines before it are
            read as strictly as ever.
        """
        with open(path, newline="") as fh:
            first = fh.readline()
            header = next(csv.reader([first]), None)
            if not header or not all(header) or (torn_tail and not first.endswith("\n")):
                raise ValueError(f"{path}: no header row (an empty or damaged trajectory CSV)")
            torn = [0]

            def whole(lines):  # the lines that end in a newline: all but a torn last one
                for line in lines:
                    if line.endswith("\n"):
                        yield line
                    else:
                        torn[0] = 1

            with warnings.catch_warnings():  # a header without rows is an empty trajectory, said by the caller
                warnings.filterwarnings("ignore", message="loadtxt: input contained no data")
                try:
                    data = np.loadtxt(whole(fh) if torn_tail else fh, delimiter=",", ndmin=2)
                except ValueError:
                    raise ValueError(f"{path}: {_bad_line(path, len(header))}") from None
        meta = {"torn_rows": torn[0]} if torn_tail else {}
        if data.size == 0:
            return cls(header, np.empty((0, len(header))), meta)
        if data.shape[1] != len(header):
            raise ValueError(f"{path}: rows have {data.shape[1]} values, the header {len(header)} columns")
        return cls(header, data, meta)

    def to_npz(self, path) -> None:
        """Write the columns and data to a numpy ``.npz`` file."""
        np.savez_compressed(path, columns=np.array(self.columns), data=self.data)

    @classmethod
    def from_npz(cls, path) -> "Trajectory":
        """Read a trajectory written by :meth:`to_npz`."""
        with np.load(path) as z:
            return cls([str(c) for c in z["columns"]], z["data"])


def _bad_line(path, width: int) -> str:
    """Why the rows of the trajectory CSV at ``path`` do not read (read again, line by line): the
    first line of another width or with a value that is not a number, counted from line 1."""
    with open(path, newline="") as fh:
        fh.readline()  # the header
        i, line = 1, ""
        for i, line in enumerate(fh, start=2):
            values = line.rstrip("\r\n").split(",")
            if not line.strip():
                continue
            if len(values) != width:
                cut = not line.endswith("\n") and not fh.read(1)
                return (f"line {i} has {len(values)} values, the header {width} columns"
                        + (" (the file ends mid-row: cut, or still being written)" if cut else ""))
            for j, v in enumerate(values):
                try:
                    float(v)
                except ValueError:
                    return f"line {i}, column {j + 1}: {v.strip()[:20]!r} is not a number"
    return "rows that do not read as numbers"
