"""Reports for CI and for people (issue 37): JUnit XML and one self-contained HTML file.

``stationbed montecarlo`` writes ``junit.xml`` and ``report.html`` in the study's folder,
``stationbed check --out DIR`` in ``DIR`` (with ``check.json``, what they are made from), and
``stationbed report DIR`` makes them again from a finished study, check or run folder.

One test case per requirement (Monte Carlo), per scene x formulation pair (check) or per run;
a case that does not pass (FAIL or NOT SHOWN, DISAGREE, a failed run) is a ``<failure>`` in the
JUnit XML, carrying the worst sample and its numbers, and a red (NOT SHOWN: amber) row of the
HTML verdict table. Modules: :mod:`.model` (the report), :mod:`.sources` (reading the folders),
:mod:`.junit`, :mod:`.html` (Jinja2 template ``report.html.j2``).
"""

from __future__ import annotations

from pathlib import Path

from ...scene import SceneError
from .model import Case, Report, Table
from .sources import check_record, check_report, run_report, study_report

__all__ = ["Case", "Report", "Table", "write_reports", "folder_report", "study_report", "check_record",
           "check_report", "run_report", "write_check", "check_outputs_of", "main", "JUNIT_NAME", "HTML_NAME",
           "CHECK_JSON"]

JUNIT_NAME = "junit.xml"
HTML_NAME = "report.html"
#: what ``stationbed check --out DIR`` records (the report is made from it)
CHECK_JSON = "check.json"


def write_reports(report: Report, folder: Path) -> tuple[Path, Path]:
    """Write ``folder/junit.xml`` and ``folder/report.html``; returns their paths."""
    from .html import write_html  # noqa: PLC0415
    from .junit import write_junit  # noqa: PLC0415

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    return write_junit(report, folder / JUNIT_NAME), write_html(report, folder / HTML_NAME)


def folder_report(folder: Path) -> Report:
    """The report of a finished folder: a Monte Carlo study (``study.json``), a check
    (``check.json``) or a run (``summary.json``); SceneError naming the folder otherwise."""
    import json  # noqa: PLC0415

    folder = Path(folder)
    if not folder.is_dir():
        raise SceneError(f"{folder}: no such folder")
    if (folder / "study.json").exists() and (folder / "summary.json").exists():
        return study_report(folder)
    if (folder / "study.json").exists():
        raise SceneError(f"{folder}: the study has not finished (study.json but no summary.json): run it again "
                         f"with --resume first")
    if (folder / CHECK_JSON).exists():
        try:
            return check_report(json.loads((folder / CHECK_JSON).read_text()))
        except (ValueError, KeyError, TypeError) as e:
            raise SceneError(f"{folder / CHECK_JSON}: damaged ({type(e).__name__}: {e})") from None
    if (folder / "summary.json").exists():
        return run_report(folder)
    raise SceneError(f"{folder}: neither a Monte Carlo study (study.json, summary.json), a check ({CHECK_JSON}) "
                     f"nor a run folder (summary.json)")


def check_outputs_of(args) -> dict[str, Path]:
    """``stationbed check``'s output files (``--rrd``; ``--out``'s check.json, junit.xml,
    report.html), to be checked against the scene file before anything runs."""
    outs = {"--rrd": args.rrd} if args.rrd else {}
    if args.out:
        outs.update({f"--out's {n}": args.out / n for n in (CHECK_JSON, JUNIT_NAME, HTML_NAME)})
    return outs


def write_check(res, scene, args) -> Report:
    """``stationbed check --out DIR``: ``DIR/check.json`` (the pairs, tolerances, scene hash,
    provenance, command), then the reports made from it."""
    import json  # noqa: PLC0415
    import os  # noqa: PLC0415

    from .sources import check_command  # noqa: PLC0415

    rec = check_record(res, scene, check_command(args), res.wall_s)
    args.out.mkdir(parents=True, exist_ok=True)
    tmp = args.out / (CHECK_JSON + ".tmp")
    tmp.write_text(json.dumps(rec, indent=2) + "\n")
    os.replace(tmp, args.out / CHECK_JSON)
    report = check_report(rec)
    write_reports(report, args.out)
    return report


def main(folder: Path) -> int:
    """``stationbed report DIR``: write DIR/junit.xml and DIR/report.html again from the folder's
    files; 0 when written (the verdicts are in the files and on the printed line)."""
    report = folder_report(folder)
    junit, html = write_reports(report, folder)
    print(f"{report.title}: {report.verdict}; wrote {junit} and {html}")
    return 0
