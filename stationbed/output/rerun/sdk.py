"""The rerun SDK, imported on first use, and the names every stationbed recording is filed under.

``import rerun`` costs ~0.3-0.5 s: it is paid only when a recording is made
(:func:`import_rerun`); ``stationbed run --rrd`` pays it in the recording child
(:mod:`stationbed.output.rerun.child`) while the parent simulates.
"""

from __future__ import annotations

__all__ = ["APPLICATION_ID", "TIMELINE", "import_rerun"]

#: Application id of every recording (run and check recordings alike).
APPLICATION_ID = "stationbed"
#: Timeline of every temporal entity: seconds since the start of the run (a rerun duration
#: timeline, stored as integer nanoseconds).
TIMELINE = "sim_time"


def import_rerun():
    """The ``rerun`` module, imported now (deferred: the import costs ~0.3-0.5 s).

    Returns
    -------
    module
        ``rerun`` (rerun-sdk).
    """
    import rerun as rr

    return rr
