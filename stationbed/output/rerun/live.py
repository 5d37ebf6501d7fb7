"""``stationbed run --realtime [FACTOR] [--hold-late] --live [URL]`` (issue 36): the run paced to
the wall clock, its recording streamed to a rerun viewer while it flies.

* ``--realtime [FACTOR]`` (1 when the factor is left out): a :class:`~stationbed.run.pacing.Pacer`
  handed to :func:`~stationbed.run.simulation.simulate`; the summary line says the factor
  achieved, the deadline misses and the lateness. The numbers are the unpaced run's.
* ``--hold-late`` (with ``--realtime``): a socket law's reply later than the next tick's deadline
  holds the last command and is counted, instead of stopping the run at ``controller.timeout``.
* ``--live [URL]``: the recording the ``--rrd`` child writes (:mod:`.child`, :class:`~.sink.RrdSink`)
  also goes to a viewer, over gRPC: ``URL`` is a running viewer's or ``rerun --serve-grpc``'s
  (``rerun+http://127.0.0.1:9876/proxy``; a bare port means that on this machine); without one, a
  viewer is started on port 9876 (``rr.spawn``; the binary ``stationbed replay`` starts:
  ``$STATIONBED_RERUN``, rerun-sdk's own, or PATH's; it needs a display). One stream, two
  sinks (rerun's ``set_sinks``): the viewer gets what the file gets, the station drawn as in a replay.
"""

from __future__ import annotations

import re
import socket

from .viewer import has_display, rerun_binary

__all__ = ["add_options", "options", "pacer", "live_url", "summary_parts", "grpc_sink", "SPAWN"]

#: ``--live`` without a URL: start a viewer
SPAWN = "spawn"
#: the port of a viewer ``--live`` starts (rerun's default)
SPAWN_PORT = 9876
#: how long ``--live URL`` waits to reach the viewer before the run [s]
CONNECT_S = 2.0


def add_options(run_parser) -> None:
    """``--realtime [FACTOR]``, ``--hold-late`` and ``--live [URL]`` of ``stationbed run``."""
    r = run_parser
    r.add_argument("--realtime", type=float, nargs="?", const=1.0, default=None, metavar="FACTOR",
                   help="pace the run to the wall clock, FACTOR times faster (default 1: real time); same numbers")
    r.add_argument("--hold-late", action="store_true",
                   help="with --realtime: a socket law's late reply holds the last command and is counted")
    r.add_argument("--live", nargs="?", const=SPAWN, default=None, metavar="URL",
                   help="stream the recording to a rerun viewer: its rerun+http://HOST:PORT/proxy URL or port "
                        "(default: start one)")


def options(args) -> tuple:
    """``(pacer, live URL)`` of ``stationbed run``'s options, checked before any output is opened."""
    return pacer(args), live_url(getattr(args, "live", None))


def pacer(args):
    """The run's :class:`~stationbed.run.pacing.Pacer` (None without ``--realtime``)."""
    if getattr(args, "hold_late", False) and args.realtime is None:
        raise ValueError("--hold-late: holds a socket law's late command under --realtime; add --realtime [FACTOR]")
    if getattr(args, "realtime", None) is None:
        return None
    from ...run.pacing import Pacer

    return Pacer(args.realtime, hold_late=args.hold_late)


def live_url(value: str | None) -> str | None:
    """``--live``'s value as the recording child takes it: a gRPC URL or :data:`SPAWN`; a bare
    port is ``rerun+http://127.0.0.1:PORT/proxy``. ValueError naming ``--live`` otherwise."""
    if value is None or value == SPAWN:
        if value == SPAWN and not has_display():
            raise ValueError("--live: no display to open a viewer on; start one where you watch (rerun, or "
                             "rerun --serve-grpc on a server) and give its URL: --live rerun+http://HOST:9876/proxy")
        return value
    url = f"rerun+http://127.0.0.1:{int(value)}/proxy" if value.isdigit() else value
    m = re.fullmatch(r"rerun(?:\+https?)?://\[?([^/\]]+?)\]?:(\d+)/proxy/?", url)
    if m is None:
        raise ValueError(f"--live {value}: give a viewer's gRPC URL, rerun+http://HOST:PORT/proxy, or a port")
    try:  # a viewer that is not there would take the stream silently: say so now
        socket.create_connection((m.group(1), int(m.group(2))), timeout=CONNECT_S).close()
    except OSError as e:
        raise ValueError(f"--live {value}: no rerun viewer or gRPC server listening at {m.group(1)}:{m.group(2)} "
                         f"({e.strerror or e}); start one (rerun, or rerun --serve-grpc) first") from None
    return url


def grpc_sink(rec, live: str):
    """The gRPC sink of ``rec`` for ``live`` (a URL, or :data:`SPAWN`: a viewer started first)."""
    import rerun as rr

    if live == SPAWN:  # the viewer `stationbed replay` starts (rerun's own search: PATH alone)
        rr.spawn(port=SPAWN_PORT, connect=False, executable_path=rerun_binary(), recording=rec)
        live = f"rerun+http://127.0.0.1:{SPAWN_PORT}/proxy"
    return rr.GrpcSink(live)


def summary_parts(s: dict) -> list[str]:
    """The run summary's words on pacing and on a socket law (cli's summary line)."""
    parts = []
    if "socket_law" in s:
        rt = f", round trip median {s['socket_round_trip_us_p50']:.0f} us" if "socket_round_trip_us_p50" in s else ""
        late = f", {s['socket_late_ticks']} late replies held" if "socket_late_ticks" in s else ""
        parts.append(f"per tick: law over a socket at {s['socket_law']}{rt}{late}")
    if "realtime_factor" in s:
        parts.append(f"paced at x{s['realtime_factor']:g} (achieved x{s['realtime_achieved_factor']:.4g}) every "
                     f"{s['realtime_paced_at']}: {s['realtime_misses']} of {s['realtime_deadlines']} deadlines missed, "
                     f"worst lateness {s['realtime_worst_late_ms']:.3g} ms, at the end {s['realtime_final_late_ms']:.3g} ms; "
                     f"work per {s['realtime_paced_at']} median {s['realtime_work_ms_p50']:.3g} ms, "
                     f"99 % {s['realtime_work_ms_p99']:.3g} ms, max {s['realtime_work_ms_max']:.3g} ms")
    return parts
