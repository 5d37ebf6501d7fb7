"""CSV output: rows streamed to ``trajectory.csv`` as a run computes them (DESIGN §6)."""

from __future__ import annotations

import io

import numpy as np

from ..run.trajectory import CSV_FORMAT

__all__ = ["CsvSink"]


class CsvSink:
    """Streams rows to a CSV file and flushes each batch (a failed run keeps its rows).

    The header line is written (and flushed) at once; values are written with ``%.17g``, so a
    row read back is the float64 row that was written.

    Parameters
    ----------
    fh : io.TextIOBase
        Open text file (``newline=""`` for plain ``\\n`` line ends).
    columns : list of str
        Column names, in row order (:func:`stationbed.run.rows.trajectory_columns`).
    """

    def __init__(self, fh: io.TextIOBase, columns: list[str]):
        self.fh = fh
        self.columns = columns
        fh.write(",".join(columns) + "\n")
        fh.flush()

    def write(self, rows: np.ndarray) -> None:
        """Append ``rows`` and flush the file.

        Parameters
        ----------
        rows : ndarray, shape (k, len(columns)) or (len(columns),)
            Values in the units of their columns (DESIGN §6).
        """
        rows = np.atleast_2d(rows)
        if rows.size:
            buf = io.StringIO()
            np.savetxt(buf, rows, delimiter=",", fmt=CSV_FORMAT)
            self.fh.write(buf.getvalue())
            self.fh.flush()
