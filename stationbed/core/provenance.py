"""What made a result: the stationbed version, the machine, the Python and the time (UTC), as
reports print it (``study.json``, ``check.json``; the HTML report's provenance)."""

from __future__ import annotations

import datetime
import os
import platform
import sys

__all__ = ["provenance"]


def provenance() -> dict:
    """``{version, machine, system, python, cpus, utc}`` of this process, now."""
    from importlib import metadata  # noqa: PLC0415

    try:
        version = metadata.version("stationbed")
    except metadata.PackageNotFoundError:  # a source tree that is not installed
        version = "unknown"
    return {"version": version, "machine": platform.node() or "localhost",
            "system": f"{platform.system()} {platform.release()} {platform.machine()}",
            "python": sys.version.split()[0], "cpus": os.cpu_count() or 1,
            "utc": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")}
