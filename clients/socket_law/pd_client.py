#!/usr/bin/env python3
"""The ``pd`` law served over a socket (stationbed's socket-law protocol, docs/socket_law.md).

Standard library only: it does not import stationbed. It listens on a TCP port; each connection
is one run (a thread each, so a Monte Carlo's samples may connect at once). The law is
controllers/pd.py's ``_update``, written out again operation for operation on Python floats, so
a run flown through it is bit-identical to the in-process ``pd``.

    python clients/socket_law/pd_client.py --port 5555
    # scene: [controller] port = "127.0.0.1:5555", period = 0.1, [controller.params] bandwidth = 0.02

``--port 0`` picks a free port; the first line on stdout is always ``listening on HOST:PORT``.
``--fault KIND@TICK`` misbehaves at a tick, for the tests: ``die`` (exit), ``late`` (sleep
``--late-s``), ``size`` (a frame without q_ref_BN), ``version`` (a frame of version 99); and
``--fault noref`` leaves the ``command q_ref_BN 4`` line out of READY.
"""

from __future__ import annotations

import argparse
import math
import os
import select
import socket
import socketserver
import struct
import sys
import time

HEADER = struct.Struct("<IHHqd")  # size of what follows this field, version, kind, tick, time [s]
VERSION = 1
HELLO, READY, MEAS, CMD, END, ERROR = 1, 2, 3, 4, 5, 6
#: how long a frame is awaited by polling the socket before sleeping in recv [s]: a thread woken
#: from a blocking recv on an idle core takes ~50 us to run again, and stationbed sends the next
#: measurement ~10 us after it reads a command (at full speed)
SPIN_S = 100e-6
EPOCH_TICKS = 256
EXPLOIT_EPOCHS = 8
SPINS_MISSED = 8


def frame(kind, tick, t, payload=b""):
    return HEADER.pack(HEADER.size - 4 + len(payload), VERSION, kind, tick, t) + payload


def parse_hello(text):
    """HELLO's lines -> (measurement offsets {name: (offset, size)}, command [(name, size)],
    params {name: [words]}, plant {name: [floats]})."""
    meas, cmd, params, plant, offset = {}, [], {}, {}, 0
    lines = [ln.split() for ln in text.splitlines() if ln.strip()]
    if lines[0] != ["stationbed-law", str(VERSION)]:
        raise ValueError(f"not a version {VERSION} HELLO: {' '.join(lines[0])}")
    for words in lines[1:]:
        key = words[0]
        if key == "measurement":
            meas[words[1]] = (offset, int(words[2]))
            offset += int(words[2])
        elif key == "command":
            cmd.append((words[1], int(words[2])))
        elif key == "param":
            params[words[1]] = words[2:]
        elif key == "plant":
            plant[words[1]] = [float(w) for w in words[2:]]
    return meas, cmd, params, plant


def qmul(p, q):
    pw, px, py, pz = p
    qw, qx, qy, qz = q
    return (pw * qw - px * qx - py * qy - pz * qz, pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx, pw * qz + px * qy - py * qx + pz * qw)


def rotate(q, v):
    w, x, y, z = q
    vx, vy, vz = v
    tx = 2.0 * (y * vz - z * vy)
    ty = 2.0 * (z * vx - x * vz)
    tz = 2.0 * (x * vy - y * vx)
    return (vx - w * tx + (y * tz - z * ty), vy - w * ty + (z * tx - x * tz), vz - w * tz + (x * ty - y * tx))


class PD:
    """controllers/pd.py: Wie's quaternion feedback, its _reset and _update on floats."""

    KNOWN = {"reference", "q_ref", "bandwidth", "damping", "max_slew_rate", "gyro_compensation"}

    def __init__(self, meas, params, plant):
        unknown = set(params) - self.KNOWN
        if unknown:
            raise ValueError(f"pd: unknown parameter '{sorted(unknown)[0]}'; valid: {', '.join(sorted(self.KNOWN))}")
        word = lambda k, d: params[k][0] if k in params else d  # noqa: E731
        reference = word("reference", "lvlh")
        q = [float(v) for v in params.get("q_ref", ["1.0", "0.0", "0.0", "0.0"])]
        n = math.sqrt(sum(v * v for v in q))  # (the scene's UnitQuaternion: normalised)
        q_ref = [v / n for v in q]
        bandwidth = float(word("bandwidth", "0.01"))
        damping = float(word("damping", "0.9"))
        max_slew_rate = float(word("max_slew_rate", "0.005"))
        self.gyro = word("gyro_compensation", "true") == "true"
        n_orbit = plant["mean_motion"][0]
        if reference == "lvlh" and math.isnan(n_orbit):
            raise ValueError("pd: reference = 'lvlh' needs an [orbit] in the scene")
        self.k = 2.0 * bandwidth**2
        self.c = 2.0 * damping * bandwidth
        J = plant["inertia_O_B"]
        self.J = ((J[0], J[1], J[2]), (J[3], J[4], J[5]), (J[6], J[7], J[8]))
        self.q_RO = tuple(q_ref)
        nn = 0.0 if math.isnan(n_orbit) else n_orbit
        self.w_RN_R = rotate(self.q_RO, (0.0, -nn, 0.0)) if reference == "lvlh" else (0.0, 0.0, 0.0)
        self.lvlh = reference == "lvlh"
        self.varying = self.lvlh and plant["lvlh_rate_varies"][0] != 0.0
        self.kc = self.k / self.c
        self.lim = max_slew_rate
        self.lim2 = max_slew_rate**2
        # where the fields the law reads are in the frame (bound by name)
        self.at = {f: meas[f][0] for f in ("q_BN", "omega_BN_B", "q_ON", "omega_ON_O")}

    def update(self, y):
        a = self.at
        i = a["q_BN"]
        qw, qx, qy, qz = y[i : i + 4]
        i = a["omega_BN_B"]
        wx, wy, wz = y[i : i + 3]
        if self.lvlh:
            i = a["q_ON"]
            rw, rx, ry, rz = qmul(y[i : i + 4], self.q_RO)
        else:
            rw, rx, ry, rz = self.q_RO
        ew = rw * qw + rx * qx + ry * qy + rz * qz
        ex = rw * qx - rx * qw - ry * qz + rz * qy
        ey = rw * qy + rx * qz - ry * qw - rz * qx
        ez = rw * qz - rx * qy + ry * qx - rz * qw
        kc = self.kc if ew >= 0.0 else -self.kc
        r0, r1, r2 = kc * ex, kc * ey, kc * ez
        rn2 = r0 * r0 + r1 * r1 + r2 * r2
        if rn2 > self.lim2:
            f = self.lim / math.sqrt(rn2)
            r0, r1, r2 = r0 * f, r1 * f, r2 * f
        if self.varying:
            i = a["omega_ON_O"]
            vx, vy, vz = rotate(self.q_RO, y[i : i + 3])
        else:
            vx, vy, vz = self.w_RN_R
        tx = 2.0 * (ey * vz - ez * vy)
        ty = 2.0 * (ez * vx - ex * vz)
        tz = 2.0 * (ex * vy - ey * vx)
        v0 = r0 + wx - (vx - ew * tx + (ey * tz - ez * ty))
        v1 = r1 + wy - (vy - ew * ty + (ez * tx - ex * tz))
        v2 = r2 + wz - (vz - ew * tz + (ex * ty - ey * tx))
        (J00, J01, J02), (J10, J11, J12), (J20, J21, J22) = self.J
        c = self.c
        t0 = -c * (J00 * v0 + J01 * v1 + J02 * v2)
        t1 = -c * (J10 * v0 + J11 * v1 + J12 * v2)
        t2 = -c * (J20 * v0 + J21 * v1 + J22 * v2)
        if self.gyro:
            Hx = J00 * wx + J01 * wy + J02 * wz
            Hy = J10 * wx + J11 * wy + J12 * wz
            Hz = J20 * wx + J21 * wy + J22 * wz
            t0 += wy * Hz - wz * Hy
            t1 += wz * Hx - wx * Hz
            t2 += wx * Hy - wy * Hx
        return (t0, t1, t2), (rw, rx, ry, rz)


class Reader:
    """Reads frames from the socket; spins (polls it for SPIN_S before a blocking recv) or blocks,
    whichever flew faster lately. A spin saves the wake-up of a thread blocked on an idle core (on
    a virtual machine, a halted vCPU: ~25-50 us); on a loaded machine it costs instead (a thread
    that never sleeps loses its turn to others' time slices). So: one epoch of EPOCH_TICKS frames
    timed each way, then EXPLOIT_EPOCHS epochs the faster way, and again; an epoch that misses
    more than SPINS_MISSED frames spinning blocks until the next cycle (as stationbed does)."""

    def __init__(self, conn):
        self.conn, poll = conn, select.poll()
        poll.register(conn, select.POLLIN)
        self.ready = poll.poll
        self.epoch, self.k, self.start, self.spin, self.timed = -1, EPOCH_TICKS, 0.0, False, [math.inf, math.inf]
        self.missed = 0  # spins missed in this epoch

    def choose(self):
        """Whether the next frame's wait spins."""
        if self.k < EPOCH_TICKS:
            self.k += 1
            return self.spin
        now = time.perf_counter()
        if self.epoch == 0:  # (too many spins missed stopped the epoch's spinning: not timed)
            self.timed[1] = now - self.start if self.spin else math.inf
        elif self.epoch == 1:
            self.timed[0] = now - self.start
        self.epoch = (self.epoch + 1) % (2 + EXPLOIT_EPOCHS)
        self.k, self.start, self.missed = 1, now, 0
        self.spin = self.epoch == 0 if self.epoch < 2 else self.timed[1] < self.timed[0]
        return self.spin

    def into(self, view, least, spin):
        """Read at least ``least`` bytes into ``view`` (at most its size: one frame); the count
        read, 0 at the end of the stream."""
        got, most = 0, len(view)
        end = time.perf_counter() + SPIN_S if spin else 0.0
        while got < least:
            if spin and not self.ready(0):
                if time.perf_counter() < end:
                    continue
                spin = False
                self.missed += 1
                if self.missed > SPINS_MISSED:  # blocking until spinning is timed again
                    self.spin, self.timed[1] = False, math.inf
            k = self.conn.recv_into(view[got:] if got else view, most - got)
            if k == 0:
                return 0
            got += k
        return got


class Run(socketserver.StreamRequestHandler):
    """One connection = one run: HELLO -> READY, then a COMMAND for every MEASUREMENT, to END."""

    rbufsize = 1 << 16

    def handle(self):
        conn, rf = self.request, self.rfile
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        fault, at = self.server.fault
        size, version, kind, tick, t = HEADER.unpack(rf.read(HEADER.size))
        text = rf.read(size + 4 - HEADER.size).decode()
        try:
            meas, cmd, params, plant = parse_hello(text)
            if cmd != [("tau_B", 3), ("q_ref_BN", 4)]:
                raise ValueError(f"pd commands a torque: this run asks for {cmd}")
            law = PD(meas, params, plant)
        except (ValueError, KeyError) as e:
            conn.sendall(frame(ERROR, -1, 0.0, str(e).encode()))
            return
        ready = ["stationbed-law 1"] + [f"command {n} {k}" for n, k in cmd if not (fault == "noref" and n == "q_ref_BN")]
        conn.sendall(frame(READY, -1, 0.0, ("\n".join(ready + ["end"]) + "\n").encode()))
        n_y = sum(k for _, k in meas.values())
        body = struct.Struct(f"<{n_y}d")
        out = struct.Struct(f"<IHHqd{3 + 4}d")
        buf, reply = bytearray(HEADER.size + body.size), bytearray(out.size)  # every frame's, made once
        view = memoryview(buf)
        reader = Reader(conn)
        read, choose = reader.into, reader.choose
        while True:
            got = read(view, HEADER.size, choose())  # the header, and the values with it when they came
            if not got:
                return  # stationbed closed the connection
            size, version, kind, tick, t = HEADER.unpack_from(buf)
            if kind == END:
                return
            if size + 4 != len(buf) or (got < len(buf) and not read(view[got:], len(buf) - got, reader.spin)):
                return
            cmd, q_ref = law.update(body.unpack_from(buf, HEADER.size))
            if tick == at:
                if fault == "die":
                    os._exit(3)
                if fault == "late":
                    time.sleep(self.server.late_s)
                if fault == "size":  # the command without q_ref_BN: a frame of 48 bytes, not 80
                    conn.sendall(frame(CMD, tick, t, struct.pack("<3d", *cmd)))
                    continue
                if fault == "version":
                    conn.sendall(out.pack(out.size - 4, 99, CMD, tick, t, *cmd, *q_ref))
                    continue
            out.pack_into(reply, 0, out.size - 4, VERSION, CMD, tick, t, *cmd, *q_ref)
            conn.sendall(reply)


class Server(socketserver.ThreadingTCPServer):
    allow_reuse_address = True
    daemon_threads = True


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--host", default="127.0.0.1")
    ap.add_argument("--port", type=int, default=5555, help="0: a free port (printed)")
    ap.add_argument("--fault", default=None, metavar="KIND@TICK", help="misbehave (tests): die, late, size, version; noref")
    ap.add_argument("--late-s", type=float, default=2.0, help="how late a 'late' fault answers [s]")
    args = ap.parse_args(argv)
    kind, _, tick = (args.fault or "").partition("@")
    with Server((args.host, args.port), Run) as srv:
        srv.fault = (kind or None, int(tick) if tick else -2)
        srv.late_s = args.late_s
        host, port = srv.server_address[:2]
        print(f"listening on {host}:{port}", flush=True)
        try:
            srv.serve_forever()
        except KeyboardInterrupt:
            pass
    return 0


if __name__ == "__main__":
    sys.exit(main())
