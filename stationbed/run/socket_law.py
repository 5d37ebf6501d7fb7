"""A law in another process, flown over a socket (``[controller] port = "host:port"``, issue 36).

The protocol is docs/socket_law.md (a client can be written from it alone); this module is
stationbed's side. In short: the law process listens on a TCP port; at the start of a run
stationbed connects, sends HELLO (the names and sizes of the measurement and command frames,
the period, the law's ``[controller.params]`` and the plant facts, as text lines) and reads
READY (the client repeats the command fields it will send, so a client built for another
layout stops at connect, naming the field). Then per tick one MEASUREMENT frame out (tick,
time, the measurement's fields, little-endian float64 in the order HELLO lists them) and one
COMMAND frame back (the command, then ``q_ref_BN``: NaN when the law has no reference); END
when the run is over. Every frame starts with the same 24-byte header ``<IHHqd``: the bytes that
follow the size field, the protocol version, the frame kind, the tick, the time [s].

Like an FMU law (:mod:`.fmu`), a socket law is a :class:`~.controller.Controller` with no
symbolic form: the run is per tick (its summary says so, naming the socket law). A client that
is late (no reply within ``[controller] timeout``), dies, refuses the handshake or sends a frame
of the wrong size, kind or version stops the run with one line naming the tick and the time;
the rows up to it are kept. Under ``--realtime`` with ``--hold-late``, a reply later than the
next tick's deadline is a miss instead: the last command is held and the miss counted
(``socket_late_ticks``); the late reply is read and dropped when it comes.

While a reply is awaited the socket is polled for a moment (:data:`SPIN_S`) or the process
sleeps in ``recv``, whichever flew faster lately (:class:`WaitChoice`; docs/design.md, "Socket
laws and real time"): a sleeping process on an idle virtual CPU wakes late, a spinning one on a
loaded machine loses its turn.
"""

from __future__ import annotations

import math
import select
import socket
import struct
import time
import weakref

import numpy as np

from .controller import Controller, ControllerError
from .measurement import measurement_fields

__all__ = ["SocketController", "SocketLawError", "SocketSetupError", "VERSION", "HEADER", "KINDS", "hello_text",
           "parse_address"]

#: the protocol's version (every frame carries it; docs/socket_law.md)
VERSION = 1
#: every frame's header: size (bytes after this field), version, kind, tick, time [s]
HEADER = struct.Struct("<IHHqd")
#: frame kinds
KINDS = {"HELLO": 1, "READY": 2, "MEASUREMENT": 3, "COMMAND": 4, "END": 5, "ERROR": 6}
HELLO, READY, MEAS, CMD, END, ERROR = (KINDS[k] for k in ("HELLO", "READY", "MEASUREMENT", "COMMAND", "END", "ERROR"))
#: the first line of a handshake text
MAGIC = "stationbed-law"
#: the reference attitude the command frame carries after the command (NaN: none)
Q_REF = ("q_ref_BN", 4)
#: the longest handshake text read [bytes]
MAX_TEXT = 1 << 20
#: between two attempts to connect to a law process that is not listening yet [s]
RETRY_S = 0.02
#: command field by command kind
COMMAND_FIELD = {"torque": ("tau_B", 3), "gimbal_rates": ("gimbal_rates", None)}
#: late ticks whose number is kept (``late_ticks``; all are counted)
LATE_TICKS_KEPT = 1000
#: how long a reply is awaited by polling the socket before blocking in the kernel [s]: a process
#: woken from a blocking ``recv`` on an idle core takes ~50 us to run again (the round trip was
#: 64-72 us so on a quiet machine, 18 us on a loaded one whose cores stay awake); a pd client
#: answers within ~2 us (C) or ~20 us (Python) of the measurement, so most replies land inside
#: the spin. Whether the wait spins at all, :class:`WaitChoice` decides (by timing both).
SPIN_S = 100e-6
#: the spin-or-block choice (:class:`WaitChoice`): ticks timed per epoch, and the epochs flown the
#: faster way before both are timed again
EPOCH_TICKS = 256
EXPLOIT_EPOCHS = 8
#: spins an epoch may miss (each costs SPIN_S, and the epoch's time counts it) before it blocks
SPINS_MISSED = 8
#: the tick and time of a frame's header (offset 8)
TICK_T = struct.Struct("<qd")
#: why a socket law keeps the run per tick (the summary's words)
PER_TICK_WHY = "the socket law (controller.port) runs in another process: it has no compiled form"


class SocketSetupError(ControllerError):
    """A socket law that cannot start (no law process, a refused or malformed handshake): one
    line naming the address."""


class SocketLawError(RuntimeError):
    """A socket law that failed during the run (late, gone, a bad frame): one line naming the
    tick and the time; the loop stops there and keeps the rows."""


def parse_address(port: str) -> tuple[str, int]:
    """``"host:port"`` or ``"port"`` (127.0.0.1) -> (host, port); SocketSetupError naming it."""
    host, _, num = port.strip().rpartition(":")
    try:
        n = int(num)
    except ValueError:
        n = -1
    if not 0 < n < 65536:
        raise SocketSetupError(f"controller.port: {port!r} is not \"host:port\" or a port number (1..65535)")
    return (host or "127.0.0.1").strip("[]"), n


def _value(v) -> str:
    """A parameter value as HELLO writes it: numbers in Python's shortest round-trip form
    (``strtod`` reads back the same double), booleans ``true``/``false``, words as they are."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(float(v)) if isinstance(v, float) else str(v)
    if isinstance(v, str) and v and not any(c.isspace() for c in v):
        return v
    raise ValueError(f"{v!r} is not a number, a boolean or a word without spaces")


def hello_text(period: float, meas_fields, cmd_fields, params: dict, plant: dict) -> str:
    """HELLO's text (docs/socket_law.md): lines ``key words...``, ending with ``end``."""
    lines = [f"{MAGIC} {VERSION}", f"period {period!r}"]
    lines += [f"measurement {n} {k}" for n, k in meas_fields]
    lines += [f"command {n} {k}" for n, k in cmd_fields]
    for name, v in params.items():
        values = v if isinstance(v, list) else [v]
        try:
            lines.append(" ".join(["param", str(name)] + [_value(x) for x in values]))
        except ValueError as e:
            raise SocketSetupError(f"controller.params.{name}: a socket law's parameter: {e}") from None
    lines += [" ".join(["plant", n] + [_value(x) for x in vals]) for n, vals in plant.items()]
    return "\n".join(lines + ["end"]) + "\n"


class SocketController(Controller):
    """A law in another process (see the module docstring and docs/socket_law.md).

    Parameters
    ----------
    port : str  ``"host:port"`` or ``"port"`` of the law process (it listens; stationbed connects).
    period : float  Controller period [s].
    params : dict  ``[controller.params]``, sent in HELLO.
    command : str  ``"torque"`` (default) or ``"gimbal_rates"``.
    timeout : float  A reply later than this [s] stops the run (also the time to connect).
    """

    name = "socket"

    def __init__(self, port: str, *, period: float = 0.1, params: dict | None = None, command: str | None = None,
                 timeout: float = 5.0):
        super().__init__(period)
        self.address = parse_address(port)
        self.name = f"socket {port.strip()}"  # messages name the law as the scene does
        self.command = command or "torque"
        self.law_params = dict(params or {})
        for key, v in self.law_params.items():  # refused now, before anything runs
            hello_text(period, [], [], {key: v}, {})
        self.timeout = float(timeout)
        self.hold_late = False  # --hold-late (with --realtime): paced_by sets the clock
        self.pacer = None
        self.sock = None
        self.n_late = 0
        self.late_ticks: list[int] = []
        self._rtt: list[float] = []

    def paced_by(self, pacer) -> None:
        """Under ``--realtime``: with :attr:`hold_late`, a reply later than the next tick's
        deadline holds the last command (counted) instead of stopping the run."""
        self.pacer = pacer
        self.hold_late = bool(getattr(pacer, "hold_late", False))

    # -- connection --------------------------------------------------------------------------
    def _where(self) -> str:
        return f"socket law at {self.address[0]}:{self.address[1]}"

    def _connect(self) -> socket.socket:
        end = time.monotonic() + self.timeout
        while True:
            try:
                s = socket.create_connection(self.address, timeout=max(0.05, end - time.monotonic()))
                break
            except (ConnectionRefusedError, socket.timeout, OSError) as e:
                if time.monotonic() >= end:
                    why = e.strerror if getattr(e, "strerror", None) else str(e) or type(e).__name__
                    raise SocketSetupError(f"controller.port: no law process listening at {self.address[0]}:"
                                           f"{self.address[1]} within {self.timeout:g} s ({why}); start it first "
                                           "(docs/socket_law.md)") from None
                time.sleep(RETRY_S)
        s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        s.settimeout(self.timeout)
        return s

    def end_run(self) -> None:
        """The run is over (:func:`~.simulation.simulate` calls it): END, and the connection closed."""
        self.close()

    def close(self) -> None:
        """Send END and close (the law process then waits for its next run)."""
        s, self.sock = self.sock, None
        if s is not None:
            _close(s, self._k)

    def _reset(self, plant) -> None:
        self.close()
        ng = plant.n_gimbals
        na = len(plant.scene.appendage) if plant.scene is not None else 0
        lay = measurement_fields(ng, na)
        meas = [(n, k) for n, (o, k) in lay.offsets().items()]
        field, size = COMMAND_FIELD[self.command]
        cmd = [(field, size if size is not None else ng), Q_REF]
        self.n_cmd = cmd[0][1]
        facts = {
            "inertia_O_B": [float(v) for v in np.asarray(plant.inertia_O_B, dtype=float).ravel()],
            "mean_motion": [float(plant.mean_motion) if plant.mean_motion is not None else math.nan],
            "lvlh_rate_varies": [int(bool(getattr(getattr(plant.scene, "orbit", None), "kepler", False)))],
            "n_gimbals": [ng],
        }
        text = hello_text(self.period, meas, cmd, self.law_params, facts)
        self._k = 0
        self.n_late = 0
        self.late_ticks = []  # the first LATE_TICKS_KEPT ticks held (--hold-late)
        self._rtt = []
        self._wait = WaitChoice()
        s = self.sock = self._connect()
        self._finalizer = weakref.finalize(self, _close, s, -1)
        try:
            s.sendall(_frame(HELLO, -1, 0.0, text.encode()))
            kind, _, _, body = _read_text(s)
        except (OSError, SocketLawError) as e:
            self.close()
            raise SocketSetupError(f"{self._where()}: handshake failed ({e})") from None
        if kind == ERROR:
            self.close()
            raise SocketSetupError(f"{self._where()}: the law process refused the run: {body.strip()}")
        if kind != READY:
            self.close()
            raise SocketSetupError(f"{self._where()}: answered HELLO with a frame of kind {kind}, expected READY ({READY})")
        self._check_ready(body, cmd)
        # the frames of every tick, made once: the measurement written into a view of its buffer
        n_y = lay.size
        self._out = bytearray(HEADER.size + 8 * n_y)
        HEADER.pack_into(self._out, 0, len(self._out) - 4, VERSION, MEAS, 0, 0.0)
        self._y = np.frombuffer(self._out, dtype="<f8", offset=HEADER.size)
        self._n_in = HEADER.size + 8 * (self.n_cmd + 4)
        self._in = bytearray(self._n_in)
        self._in_view = memoryview(self._in)
        self._vals = np.frombuffer(self._in, dtype="<f8", offset=HEADER.size)
        self._last = (0.0,) * self.n_cmd
        # per tick the socket blocks, bounded by timeout in the kernel (Python's own timeout would
        # poll before every send and recv: a system call each): one send and one recv a tick
        s.settimeout(None)
        bound = struct.pack("@ll", int(self.timeout), max(int(self.timeout % 1.0 * 1e6), 1))  # timeval; 0 is forever
        s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVTIMEO, bound)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_SNDTIMEO, bound)
        self._poll = select.poll()
        self._poll.register(s, select.POLLIN)

    def _check_ready(self, body: str, cmd) -> None:
        lines = [ln.split() for ln in body.splitlines() if ln.strip()]
        where = self._where()
        if not lines or lines[0][:1] != [MAGIC]:
            self.close()
            raise SocketSetupError(f"{where}: READY does not start with '{MAGIC} {VERSION}'")
        if lines[0][1:] != [str(VERSION)]:
            self.close()
            raise SocketSetupError(f"{where}: READY speaks version {' '.join(lines[0][1:])}, stationbed {VERSION}")
        said = [ln[1:] for ln in lines if ln[0] == "command"]
        for name, size in cmd:
            if [name, str(size)] not in said:
                self.close()
                got = ", ".join(" ".join(c) for c in said) or "none"
                raise SocketSetupError(f"{where}: READY lacks the field 'command {name} {size}' (it said: {got}); "
                                       "the command frame is " + ", ".join(f"{n} ({k})" for n, k in cmd))

    # -- a tick ------------------------------------------------------------------------------
    def _update(self, t, meas):
        k = self._k
        self._k = k + 1
        if self.sock is None:
            raise SocketLawError(f"tick {k} (t = {t:.6g} s): the connection is closed")
        out = self._out
        TICK_T.pack_into(out, 8, k, t)
        self._y[:] = meas.y
        t0 = time.perf_counter()
        self._send(k, t)
        limit = None
        if self.hold_late and self.pacer is not None:  # until the next tick's deadline
            limit = self.pacer.deadline(t + self.period)
        while True:
            if not self._receive(k, t, limit):  # late under --hold-late: the last command held, the miss counted
                self.n_late += 1
                if len(self.late_ticks) < LATE_TICKS_KEPT:
                    self.late_ticks.append(k)
                return self._last
            tick = TICK_T.unpack_from(self._in, 8)[0]
            if tick == k:
                break
            if tick > k or not self.hold_late:
                self.close()
                raise SocketLawError(f"tick {k} (t = {t:.6g} s): the law process answered for tick {tick}")
        self._rtt.append(time.perf_counter() - t0)
        v = self._vals.tolist()
        n = self.n_cmd
        cmd = tuple(v[:n])
        q = v[n:]
        self.q_ref_BN = None if q[0] != q[0] else q  # NaN: the law has no reference
        self._last = cmd
        return cmd

    def _send(self, k: int, t: float) -> None:
        """The measurement frame out (a client that reads nothing for ``timeout``: late)."""
        try:
            self.sock.sendall(self._out)
        except BlockingIOError:  # SO_SNDTIMEO: the send buffer stayed full
            self.close()
            raise SocketLawError(f"tick {k} (t = {t:.6g} s): the law process reads no measurement within "
                                 f"{self.timeout:g} s (the law process is late)") from None
        except OSError as e:
            self.close()
            raise SocketLawError(f"tick {k} (t = {t:.6g} s): the law process is gone ({e.strerror or e})") from None

    def _receive(self, k: int, t: float, limit) -> bool:
        """Read one COMMAND frame into ``_in``: False when the wall clock passed ``limit``
        (``perf_counter``; hold-late) before any of it came. The socket is polled for
        :data:`SPIN_S` when :class:`WaitChoice` says so; then ``recv`` sleeps, up to ``timeout``
        (or ``poll`` until ``limit``)."""
        s, view, need, ready = self.sock, self._in_view, self._n_in, self._poll.poll
        got = 0
        start = time.perf_counter()
        spin = self._wait.tick(start)
        try:
            while got < need:
                if spin and not ready(0):  # nothing yet: spin a little
                    if time.perf_counter() < start + SPIN_S:
                        continue
                    self._wait.missed()
                    spin = False
                if limit is not None and not spin:  # --hold-late: until the next tick's deadline
                    left = limit - time.perf_counter()
                    if left <= 0.0 or not ready(left * 1e3):
                        if got == 0:
                            return False
                        self._late(k, t, limit - start, got)
                try:
                    n = s.recv_into(view[got:] if got else view, need - got)
                except BlockingIOError:  # SO_RCVTIMEO: nothing within timeout
                    self._late(k, t, self.timeout, got)
                if n == 0:
                    self.close()
                    raise SocketLawError(f"tick {k} (t = {t:.6g} s): the law process closed the connection")
                got += n
                if got >= 8:
                    self._check_header(k, t)
        except ConnectionError as e:
            self.close()
            raise SocketLawError(f"tick {k} (t = {t:.6g} s): the law process is gone ({e.strerror or e})") from None
        return True

    def _late(self, k: int, t: float, waited_s: float, got: int):
        self.close()
        raise SocketLawError(f"tick {k} (t = {t:.6g} s): no command within {waited_s:g} s "
                             f"(the law process is late{'; partial frame' if got else ''})")

    def _check_header(self, k: int, t: float) -> None:
        size, version, kind = struct.unpack_from("<IHH", self._in, 0)
        if version != VERSION:
            self.close()
            raise SocketLawError(f"tick {k} (t = {t:.6g} s): a frame of version {version}, expected {VERSION}")
        if kind != CMD:
            self.close()
            what = "an ERROR frame (the law failed)" if kind == ERROR else f"a frame of kind {kind}"
            raise SocketLawError(f"tick {k} (t = {t:.6g} s): {what}, expected COMMAND ({CMD})")
        if size != self._n_in - 4:
            self.close()
            raise SocketLawError(f"tick {k} (t = {t:.6g} s): a COMMAND frame of {size + 4} bytes, expected "
                                 f"{self._n_in} ({self.n_cmd} command values and q_ref_BN (4), float64)")

    def summary(self) -> dict:
        out = {"socket_law": f"{self.address[0]}:{self.address[1]}", "executor_per_tick_because": PER_TICK_WHY}
        if self._rtt:
            r = np.array(self._rtt) * 1e6
            out.update(socket_round_trip_us_p50=float(np.percentile(r, 50)),
                       socket_round_trip_us_p999=float(np.percentile(r, 99.9)))
        if self.hold_late:
            out["socket_late_ticks"] = self.n_late
        return out


class WaitChoice:
    """Spin or block while a reply is awaited: whichever flew faster lately.

    A spin (the socket polled for :data:`SPIN_S` before sleeping in ``poll``) saves the wake-up of
    a process blocked on an idle core (on a virtual machine, a halted vCPU woken by an interrupt:
    ~25-50 us each way); on a loaded machine it costs instead (a process that never sleeps loses its
    turn to other processes' time slices; two processes that spin on one core each wait out the
    other's spin). Which one wins is only known by trying: one epoch of :data:`EPOCH_TICKS` ticks
    timed each way (wall time, everything in the tick), then :data:`EXPLOIT_EPOCHS` epochs flown
    the faster way, and again; an epoch whose spins miss the reply too often stops spinning until
    the next cycle.
    Numbers never depend on it.
    """

    def __init__(self):
        self.epoch = -1  # into the cycle: 0 timed spinning, 1 timed blocking, then the faster way
        self.k = EPOCH_TICKS  # ticks into the epoch
        self.start = 0.0  # when the epoch began [s, perf_counter]
        self.spin = False
        self.timed = [math.inf, math.inf]  # s: the last epoch timed blocking, spinning
        self.n_missed = 0  # spins missed in this epoch

    def tick(self, now: float) -> bool:
        """Whether this tick's wait spins (``now``: ``perf_counter`` at the tick)."""
        if self.k < EPOCH_TICKS:
            self.k += 1
            return self.spin
        if self.epoch == 0:  # (too many spins missed stopped the epoch's spinning: not timed)
            self.timed[1] = now - self.start if self.spin else math.inf
        elif self.epoch == 1:
            self.timed[0] = now - self.start
        self.epoch = (self.epoch + 1) % (2 + EXPLOIT_EPOCHS)
        self.k, self.start, self.n_missed = 1, now, 0
        self.spin = self.epoch == 0 if self.epoch < 2 else self.timed[1] < self.timed[0]
        return self.spin

    def missed(self) -> None:
        """A spin that ended before the reply came (the peer shares this core, is slow, or was
        preempted): more than :data:`SPINS_MISSED` in an epoch, and the wait blocks until
        spinning is timed again (a timed epoch so ended is not a spinning one)."""
        self.n_missed += 1
        if self.n_missed > SPINS_MISSED:
            self.spin = False
            self.timed[1] = math.inf


# -- frames ----------------------------------------------------------------------------------
def _frame(kind: int, tick: int, t: float, payload: bytes = b"") -> bytes:
    return HEADER.pack(HEADER.size - 4 + len(payload), VERSION, kind, tick, t) + payload


def _read_exact(s: socket.socket, n: int) -> bytes:
    buf = bytearray()
    while len(buf) < n:
        chunk = s.recv(n - len(buf))
        if not chunk:
            raise SocketLawError("the law process closed the connection")
        buf += chunk
    return bytes(buf)


def _read_text(s: socket.socket) -> tuple[int, int, float, str]:
    """A handshake frame: (kind, tick, t, its text)."""
    size, version, kind, tick, t = HEADER.unpack(_read_exact(s, HEADER.size))
    if version != VERSION:
        raise SocketLawError(f"a frame of version {version}, expected {VERSION}")
    n = size + 4 - HEADER.size
    if not 0 <= n <= MAX_TEXT:
        raise SocketLawError(f"a handshake frame of {size + 4} bytes")
    return kind, tick, t, _read_exact(s, n).decode("utf-8", "replace")


def _close(s: socket.socket, tick: int) -> None:
    try:
        s.settimeout(0.5)
        s.sendall(_frame(END, tick, math.nan))
    except OSError:
        pass  # the law process is gone: nothing to tell it
    try:
        s.close()
    except OSError:
        pass

