"""Named layouts of flat vectors: declared once, they own the indices.

A :class:`Layout` names the pieces of a flat vector (a sensor's state, its parameters, its
measurement, the truth a sensor reads, the filter's state): ``L = Layout(q_BN=4, bias_B=3,
P=(6, 6))``. Code reads ``L.get(x, "bias_B")`` and builds vectors with ``L.pack(...)``; nobody
writes ``x[4:7]``. The same calls work on numpy arrays (1-D, or 2-D with one row per sample)
and on casadi column vectors, so a layout serves the compiled expression and every executor.

Matrix fields are stored column-major (casadi's order): ``get`` returns the matrix, ``pack``
flattens it the same way.
"""

from __future__ import annotations

from collections.abc import Mapping

import casadi as ca
import numpy as np

from .symbolic import is_symbolic

__all__ = ["Layout"]

#: column suffixes of 3-vectors and scalar-first quaternions (DESIGN §3 column names)
_AXES = {3: ("x", "y", "z"), 4: ("w", "x", "y", "z")}


class Layout:
    """Named, ordered slices of a flat vector.

    Parameters
    ----------
    **fields : int or (int, int)
        Field name -> size (a vector of that many numbers; 0 for a field a run may not have,
        e.g. no gimbals) or (rows, cols) (a matrix, stored column-major). The keyword order is
        the order in the vector.

    Examples
    --------
    >>> L = Layout(q_BN=4, bias_B=3)
    >>> L.size, L.slice("bias_B")
    (7, slice(4, 7, None))
    """

    def __init__(self, **fields: int | tuple[int, int]):
        self._shape: dict[str, tuple[int, int]] = {}
        self._slice: dict[str, slice] = {}
        at = 0
        for name, shape in fields.items():
            rows, cols = (shape, 1) if isinstance(shape, (int, np.integer)) else tuple(shape)
            if rows < 0 or cols < 1:
                raise ValueError(f"layout field {name!r}: size must not be negative, got {shape!r}")
            self._shape[name] = (int(rows), int(cols))
            self._slice[name] = slice(at, at + rows * cols)
            at += rows * cols
        self.size = at

    # -- what it declares ----------------------------------------------------------------
    @property
    def names(self) -> tuple[str, ...]:
        """The field names, in order."""
        return tuple(self._slice)

    def __contains__(self, name: str) -> bool:
        return name in self._slice

    def __len__(self) -> int:
        return self.size

    def __eq__(self, other) -> bool:
        return isinstance(other, Layout) and self._shape == other._shape

    def __hash__(self) -> int:
        return hash(tuple(self._shape.items()))

    def __repr__(self) -> str:
        inner = ", ".join(f"{n}={s[0] if s[1] == 1 else s}" for n, s in self._shape.items())
        return f"Layout({inner})"

    def slice(self, name: str) -> slice:
        """The indices of field ``name``."""
        try:
            return self._slice[name]
        except KeyError:
            raise KeyError(f"no field {name!r} in {self!r}") from None

    def shape(self, name: str) -> tuple[int, int]:
        """(rows, cols) of field ``name`` (cols = 1 for a vector)."""
        self.slice(name)
        return self._shape[name]

    def offsets(self) -> dict[str, tuple[int, int]]:
        """Field name -> (offset, size): the plain-dict form (what older code reads, e.g.
        ``stationbed.run.controller.measurement_layout``)."""
        return {n: (s.start, s.stop - s.start) for n, s in self._slice.items()}

    def columns(self, prefix: str = "") -> list[str]:
        """Column names, one per number: ``<prefix><field>_<axis>`` (``_x, _y, _z`` for a
        3-vector, ``_w, _x, _y, _z`` for a quaternion field named ``q_*``, ``_<i>`` otherwise,
        nothing for a scalar)."""
        out = []
        for name, (rows, cols) in self._shape.items():
            n = rows * cols
            if n == 1:
                out.append(prefix + name)
                continue
            axes = _AXES.get(n) if cols == 1 and (n == 3 or name.startswith("q_")) else None
            out += [f"{prefix}{name}_{a}" for a in (axes or range(n))]
        return out

    # -- reading and writing -------------------------------------------------------------
    def get(self, v, name: str):
        """Field ``name`` of ``v``.

        ``v`` is a casadi column (returns a column, or the matrix), a numpy vector of shape
        (size,) (returns (n,) or the (rows, cols) matrix) or a numpy table of shape
        (N, size) (returns (N, n) or (N, rows, cols)).
        """
        s = self.slice(name)
        rows, cols = self._shape[name]
        if is_symbolic(v):
            part = v[s]
            return ca.reshape(part, rows, cols) if cols > 1 else part
        v = np.asarray(v)
        if v.shape[-1] != self.size:
            raise ValueError(f"{self!r}: vector has {v.shape[-1]} numbers, the layout {self.size}")
        part = v[..., s]
        if cols > 1:
            return part.reshape(v.shape[:-1] + (cols, rows)).swapaxes(-1, -2)
        return part

    def split(self, v) -> dict:
        """Every field of ``v`` by name (see :meth:`get`)."""
        return {name: self.get(v, name) for name in self._slice}

    def pack(self, values: Mapping | None = None, /, symbolic: bool = False, **more):
        """The flat vector of the named fields, in layout order (every field once).

        A casadi value anywhere (or ``symbolic=True``: always, e.g. for a layout without fields) makes a
        casadi column; otherwise a numpy float64 vector of shape (size,). Matrix fields are
        flattened column-major.
        """
        values = {**(values or {}), **more}
        missing = [n for n in self._slice if n not in values]
        extra = [n for n in values if n not in self._slice]
        if missing or extra:
            raise ValueError(f"{self!r}: missing fields {missing}, unknown fields {extra}")
        if symbolic or any(is_symbolic(v) for v in values.values()):
            parts = []
            for name, (rows, cols) in self._shape.items():
                part = ca.vec(ca.DM(values[name]) if not is_symbolic(values[name]) else values[name])
                if part.numel() != rows * cols:
                    raise ValueError(f"layout field {name!r}: {part.numel()} numbers, expected {rows * cols}")
                parts.append(part)
            return ca.vertcat(*parts) if parts else ca.SX(0, 1)
        out = np.empty(self.size)
        for name, (rows, cols) in self._shape.items():
            part = np.asarray(values[name], dtype=float)
            flat = part.T.ravel() if part.ndim == 2 else part.ravel()
            if flat.size != rows * cols:
                raise ValueError(f"layout field {name!r}: {flat.size} numbers, expected {rows * cols}")
            out[self._slice[name]] = flat
        return out

    def zeros(self) -> np.ndarray:
        """A numpy vector of zeros, shape (size,)."""
        return np.zeros(self.size)

    def symbol(self, name: str, kind=ca.SX):
        """A casadi column of this layout's size (``kind``: ``casadi.SX`` or ``casadi.MX``)."""
        return kind.sym(name, self.size)
