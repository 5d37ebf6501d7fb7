"""A :class:`~.model.Report` as one self-contained HTML file: the verdict table (``#verdicts``,
one row per case: ``pass``, ``fail`` in red, ``notshown`` in amber), the failed cases' details,
the tables, the charts inline (``data:`` URIs) and the provenance. No script, no style sheet,
font or image from elsewhere: it opens offline. Rendered by Jinja2 (``report.html.j2`` beside
this module, autoescaped)."""

from __future__ import annotations

import os
from pathlib import Path

from .model import Case, Report

__all__ = ["render_html", "write_html", "row_class"]


def row_class(case: Case) -> str:
    """The verdict row's class: ``pass``; ``notshown`` (no sample failed; too few samples to show
    it); ``fail`` (a sample, a pair or the run failed)."""
    if case.passed:
        return "pass"
    return "notshown" if case.verdict == "NOT SHOWN" else "fail"


def render_html(report: Report) -> str:
    """The HTML text of ``report``."""
    import jinja2  # noqa: PLC0415 - only when a report is written

    env = jinja2.Environment(loader=jinja2.FileSystemLoader(str(Path(__file__).parent)),
                             autoescape=True, undefined=jinja2.StrictUndefined, keep_trailing_newline=True)
    return env.get_template("report.html.j2").render(report=report, row_class=row_class)


def write_html(report: Report, path: Path) -> Path:
    """Write :func:`render_html` to ``path`` (through a temporary file)."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(render_html(report), encoding="utf-8")
    os.replace(tmp, path)
    return path
