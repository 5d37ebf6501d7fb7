"""What every stability case shares: its result (:class:`Case`), the context it runs in, and
the registry through which the study finds it.

A case is a function ``run(ctx) -> Case`` registered under its name with
:func:`stability_case`. Rules for a case:

1. It builds its scenes, runs every method it compares, and adds one verdict per method
   (:meth:`Case.add`): a method that refuses the scene or breaks down is a verdict too.
2. Its :class:`Case` carries ``ctx.name``, a title and the detector (what is measured and the
   threshold of the verdict, in words).
3. It draws one figure and writes it with its rows through :meth:`Context.save`
   (``stability_<name>.png`` / ``.csv`` in ``ctx.out``).
4. ``ctx.quick`` shrinks it to seconds (tests, CI) without changing what it detects.
5. Before each run (or other work of more than a second) it says what it starts with
   :meth:`Context.note` (``"rk4/momentum h 4 s"``): the study's progress shows it, so a long
   case is never silent.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from ..common import write_csv

__all__ = ["Case", "Context", "STABILITY_CASES", "stability_case"]


@dataclass
class Case:
    """One stability case's result: what it detects, a verdict per method, and its files.

    Attributes
    ----------
    name : str
        The registry name (file names ``stability_<name>.*``).
    title : str
    detector : str
        What is measured, and the threshold of the verdict.
    verdicts : list of dict
        ``method``, ``value``, ``unit``, ``verdict`` per method.
    files : list of Path
        The case's CSV and PNG.
    """

    name: str
    title: str
    detector: str
    verdicts: list[dict] = field(default_factory=list)  # method, value, unit, verdict
    files: list[Path] = field(default_factory=list)

    def add(self, method: str, value: float, unit: str, verdict: str) -> None:
        """Add a method's verdict (``value`` in ``unit``; NaN when the method did not run)."""
        self.verdicts.append({"method": method, "value": value, "unit": unit, "verdict": verdict})


@dataclass
class Context:
    """Where and how one case runs.

    Attributes
    ----------
    name : str
        The case's registry name.
    out : Path
        Output folder.
    quick : bool
        Shrink the case to seconds.
    plt : module
        ``matplotlib.pyplot`` (headless).
    log : callable
        Result lines.
    note : callable
        ``note(text)``: what the case starts now, for the progress display (default: ignored).
    """

    name: str
    out: Path
    quick: bool
    plt: object
    log: object
    note: Callable[[str], None] = field(default=lambda text: None)

    def save(self, case: Case, fig, rows, header) -> None:
        """Write the case's figure and rows (``stability_<name>.png`` / ``.csv``), close the
        figure, and add both files to ``case.files``."""
        png = self.out / f"stability_{case.name}.png"
        fig.savefig(png, dpi=110)
        self.plt.close(fig)
        csv_path = self.out / f"stability_{case.name}.csv"
        write_csv(csv_path, header, rows)
        case.files += [csv_path, png]


#: the registered cases, name -> ``run(ctx) -> Case``, in registration order (the study's order)
STABILITY_CASES: dict[str, Callable[[Context], Case]] = {}


def stability_case(name: str):
    """Decorator: register a case function under ``name``.

    Parameters
    ----------
    name : str
        Registry name (also in the case's file names and the summary's ``case`` column).

    Raises
    ------
    ValueError
        ``name`` is already registered.
    """

    def register(run: Callable[[Context], Case]) -> Callable[[Context], Case]:
        if name in STABILITY_CASES:
            raise ValueError(f"stability case {name!r} is registered twice")
        STABILITY_CASES[name] = run
        return run

    return register
