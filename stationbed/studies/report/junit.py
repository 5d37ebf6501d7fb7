"""A :class:`~.model.Report` as JUnit XML, the Apache Ant form that CI servers read (Jenkins,
GitLab, GitHub actions' test reporters): ``<testsuites>`` holding one ``<testsuite>`` (with
``package``, ``id``, ``timestamp``, ``hostname``, ``<properties>``, ``<system-out>`` and
``<system-err>``, every one the schema requires), one ``<testcase>`` per case, a failed case
with ``<failure message type>`` whose text is the case's details. Written with
:mod:`xml.etree.ElementTree`; tests/test_reports.py validates it against the schema
(tests/data/junit/JUnit.xsd)."""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from pathlib import Path

from .model import Report

__all__ = ["junit_xml", "write_junit"]

#: the ``type`` of a failure: the verdict word, so a CI page groups FAIL apart from NOT SHOWN
FAILURE_TYPE = "stationbed.{verdict}"


def junit_xml(report: Report) -> bytes:
    """The JUnit XML document of ``report`` (UTF-8 bytes with the XML declaration)."""
    failures = sum(not c.passed for c in report.cases)
    root = ET.Element("testsuites")
    suite = ET.SubElement(root, "testsuite", {
        "name": report.suite, "package": report.kind, "id": "0", "timestamp": report.utc,
        "hostname": str(report.provenance.get("machine") or "localhost"), "tests": str(len(report.cases)),
        "failures": str(failures), "errors": "0", "skipped": "0", "time": f"{report.time_s:.3f}"})
    props = ET.SubElement(suite, "properties")
    for k, v in report.provenance.items():
        ET.SubElement(props, "property", {"name": str(k), "value": str(v)})
    share = report.time_s / max(len(report.cases), 1)  # the study's time, shared by its cases
    for c in report.cases:
        case = ET.SubElement(suite, "testcase", {"name": c.name, "classname": c.suite, "time": f"{share:.3f}"})
        if not c.passed:
            fail = ET.SubElement(case, "failure", {"message": c.message or c.verdict,
                                                   "type": FAILURE_TYPE.format(verdict=c.verdict.replace(" ", "_"))})
            fail.text = c.details or c.message
    ET.SubElement(suite, "system-out").text = "\n".join(report.lines)
    ET.SubElement(suite, "system-err").text = ""
    ET.indent(root)
    return ET.tostring(root, encoding="utf-8", xml_declaration=True) + b"\n"


def write_junit(report: Report, path: Path) -> Path:
    """Write :func:`junit_xml` to ``path`` (through a temporary file: never half a file)."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_bytes(junit_xml(report))
    os.replace(tmp, path)
    return path
