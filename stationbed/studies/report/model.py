"""What a report holds, whatever made it: test cases (one per requirement, formulation pair or
run), tables, charts and provenance. :mod:`.junit` and :mod:`.html` write the same
:class:`Report`, so a case failed in the JUnit XML is the row shown red in the HTML."""

from __future__ import annotations

import base64
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["Case", "Table", "Report", "png_data_uri"]


@dataclass
class Case:
    """One test case of a report.

    ``suite`` is the JUnit ``classname`` (``montecarlo.<scene>``, ``check.<scene>``,
    ``run.<scene>``); ``verdict`` the printed word (PASS, FAIL, NOT SHOWN; ok, DISAGREE; the
    run's status); ``message`` one line (the failure's ``message``); ``details`` the failure's
    text: the worst sample, its numbers and the command that replays it. ``id`` and ``text``
    are the requirement's identifier and wording (``[[montecarlo.requirement]] id, text``)."""

    suite: str
    name: str
    verdict: str
    passed: bool
    message: str = ""
    details: str = ""
    id: str | None = None
    text: str | None = None
    numbers: str = ""  # the bounds shown beside the verdict (confidence bound, differences)


@dataclass
class Table:
    """A table of the HTML report: a title, column heads and rows of text (``failed`` rows red)."""

    title: str
    head: list[str]
    rows: list[list[str]]
    failed: list[bool] = field(default_factory=list)
    note: str = ""
    code_column: int | None = None  # the column holding a command (monospace, selectable)


@dataclass
class Report:
    """Everything :func:`~.write_reports` writes: the cases (the verdict table and the JUnit
    test cases), more tables, charts (``(caption, data URI)``), the summary lines and the
    provenance (version, scene hash, seed, machine, ...)."""

    title: str
    kind: str  # montecarlo, check, run
    suite: str
    cases: list[Case]
    tables: list[Table] = field(default_factory=list)
    charts: list[tuple[str, str]] = field(default_factory=list)
    lines: list[str] = field(default_factory=list)
    provenance: dict = field(default_factory=dict)
    time_s: float = 0.0
    utc: str = ""  # when the result was made, ISO 8601 (UTC, no zone: the JUnit schema's form)

    @property
    def ok(self) -> bool:
        """Whether every case passed."""
        return all(c.passed for c in self.cases)

    @property
    def verdict(self) -> str:
        """PASS, or FAIL with the number of failed cases."""
        bad = sum(not c.passed for c in self.cases)
        return "PASS" if not bad else f"FAIL ({bad} of {len(self.cases)})"


def png_data_uri(path: Path) -> str:
    """A PNG file as a ``data:`` URI (the HTML report holds its charts inline: no file, no network)."""
    return "data:image/png;base64," + base64.b64encode(Path(path).read_bytes()).decode("ascii")
