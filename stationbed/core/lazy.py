"""Names a package imports on first use (PEP 562): ``import stationbed`` must stay light (the
command line starts ``run --rrd``'s recording process before casadi, scipy and pydantic are
imported), and the command line registers its parsers without importing what they run."""

from __future__ import annotations

import importlib
import sys

__all__ = ["lazy_names"]


def lazy_names(package: str, table: dict[str, str]):
    """The ``__getattr__`` and ``__dir__`` of a package whose names load on first use.

    Parameters
    ----------
    package : str  The package's ``__name__``.
    table : dict  name -> the submodule that defines it, relative to ``package``.

    Returns
    -------
    (callable, callable)  Module-level ``__getattr__`` (imports the name once, then keeps it in
    the package's namespace) and ``__dir__``.
    """

    def __getattr__(name):
        mod = table.get(name)
        if mod is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(f".{mod}", package), name)
        setattr(sys.modules[package], name, value)
        return value

    def __dir__():
        return sorted(set(vars(sys.modules[package])) | set(table))

    return __getattr__, __dir__
