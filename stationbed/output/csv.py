"""CSV output: rows streamed to ``trajectory.csv`` as a run computes them (DESIGN §6)."""

from __future__ import annotations

import io

import numpy as np

__all__ = ["CsvSink"]


class CsvSink:
    """Streams rows to a CSV file and flushes each batch (a failed run keeps its rows)."""

    def __init__(self, fh: io.TextIOBase, columns: list[str]):
        self.fh = fh
        self.columns = columns
        fh.write(",".join(columns) + "\n")
        fh.flush()

    def write(self, rows: np.ndarray) -> None:
        rows = np.atleast_2d(rows)
        if rows.size:
            buf = io.StringIO()
            np.savetxt(buf, rows, delimiter=",", fmt="%.17g")
            self.fh.write(buf.getvalue())
            self.fh.flush()
