"""CSV output: rows streamed to ``trajectory.csv`` as a run computes them (DESIGN §6).

Each batch goes to the file in whole rows: written straight to the file descriptor (no Python
buffer left to flush later), and when a write fails (disk full, file-size limit, Ctrl-C in the
middle of a write) the file is cut back to the end of the last complete row and
:class:`~stationbed.run.rows.SinkError` names the file and that row's time. A process killed
with SIGKILL while the kernel is writing a batch may still leave that batch's tail torn.
"""

from __future__ import annotations

import io
import os

import numpy as np

from ..run.rows import SinkError
from ..run.trajectory import CSV_FORMAT

__all__ = ["CsvSink", "SinkError"]


class CsvSink:
    """Streams rows to a CSV file, one whole batch per write (a failed run keeps its rows).

    The header line is written at once; values are written with ``%.17g``, so a row read back
    is the float64 row that was written.

    Parameters
    ----------
    fh : str, path or file object
        A path (the file is created or truncated, and closed by :meth:`close` or ``with``), or an
        open file (text, ``newline=""``, or binary). A file with a descriptor (a real file) is
        written through it, whole rows only; another one (``io.StringIO``) through ``write``.
    columns : list of str
        Column names, in row order (:func:`stationbed.run.rows.trajectory_columns`).

    Attributes
    ----------
    path : str
        The file's name (``fh.name``, or ``"<stream>"``).
    rows_written : int
        Complete rows in the file.
    last_t : float or None
        Time of the last complete row (None: the header only).

    Raises
    ------
    SinkError
        From the constructor or :meth:`write`: the write failed; the file ends with the last
        complete row (or the header, or is empty when the header did not fit).
    """

    def __init__(self, fh, columns: list[str]):
        self._own = isinstance(fh, (str, os.PathLike))
        if self._own:
            fh = open(fh, "wb", buffering=0)
        self.fh = fh
        self.columns = columns
        self._line = ",".join([CSV_FORMAT] * len(columns)) + "\n"
        self.path = str(getattr(fh, "name", "<stream>"))
        self.rows_written = 0
        self.last_t = None
        self._failed = None
        self._header_done = False
        try:
            fh.flush()
            self._fd = fh.fileno()
            self._end = os.lseek(self._fd, 0, os.SEEK_CUR)
        except (AttributeError, OSError, io.UnsupportedOperation):
            self._fd = None  # no descriptor (an in-memory stream): its own write
            self._text = isinstance(fh, io.TextIOBase)
        self._write((",".join(columns) + "\n").encode())

    def write(self, rows: np.ndarray) -> None:
        """Append ``rows`` as whole lines, or raise :class:`SinkError` leaving none torn.

        Parameters
        ----------
        rows : ndarray, shape (k, len(columns)) or (len(columns),)
            Values in the units of their columns (DESIGN §6).
        """
        rows = np.atleast_2d(rows)
        if rows.size:
            # np.savetxt's lines (CSV_FORMAT joined by commas), formatted in one operation
            self._write(((self._line * len(rows)) % tuple(rows.ravel().tolist())).encode())
            self.rows_written += len(rows)
            self.last_t = float(rows[-1, 0])

    def _write(self, data: bytes) -> None:
        if self._failed is not None:  # never write past a failure (the file was cut back)
            raise self._failed
        if self._fd is None:
            try:
                self.fh.write(data.decode() if self._text else data)
                self.fh.flush()
            except OSError as e:  # a stream without a descriptor: no cutting back
                self._failed = SinkError(self.path, self.last_t, e, f"{self._held()}, maybe a torn last line")
                raise self._failed from e
            return
        done = 0
        try:
            view = memoryview(data)
            while done < len(data):
                done += os.write(self._fd, view[done:])
        except BaseException as e:
            torn = False
            if done:  # cut the partial batch off: the file ends with the last complete row
                try:
                    os.ftruncate(self._fd, self._end)
                    os.lseek(self._fd, self._end, os.SEEK_SET)
                except OSError:
                    torn = True
            if isinstance(e, OSError):
                if torn:
                    held = f"a torn last line (it could not be cut back after {self._held()})"
                else:
                    held = self._held() if self._header_done else "nothing (the header did not fit)"
                self._failed = SinkError(self.path, self.last_t, e, held)
                raise self._failed from e
            raise
        self._end += done
        self._header_done = True

    def _held(self) -> str:
        return "only the header" if self.last_t is None else f"the rows up to t = {self.last_t:.10g} s"

    def close(self) -> None:
        """Close the file when the sink opened it (a file object passed in stays open)."""
        if self._own and not self.fh.closed:
            self.fh.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
