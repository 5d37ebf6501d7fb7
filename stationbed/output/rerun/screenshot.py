"""A recording as the rerun web viewer shows it, rendered in headless Chromium to a PNG (issue 24).

``stationbed screenshot REC.rrd --out PNG`` serves the recording's file over HTTP and the web
viewer with the viewer binary that rerun-sdk installs (``rerun --web-viewer http://.../REC.rrd``,
both on 127.0.0.1, free ports; the viewer fetches the file itself), opens the web
viewer in headless Chromium (software WebGL: SwiftShader through ANGLE) and drives it over the
DevTools protocol on a pipe (``--remote-debugging-pipe``: NUL-terminated JSON on file descriptors
3 and 4, so nothing beyond the standard library and no debugging port): it waits until the viewer's
canvas is up and its loading screen is gone, then captures the page (``Page.captureScreenshot``)
every ``settle_s`` seconds until two captures are the same picture (the software-rendered viewer
takes tens of seconds to take in a file) and writes that one. The browser is the system's (Debian package ``chromium``,
``make screenshots`` installs it); without one :func:`find_browser` returns None and the command
says so and exits 1.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

# (base64, socket, subprocess, tempfile, urllib are imported where used: the command line imports
# this module for its parser, and every import there is start-up time of every command)

__all__ = ["find_browser", "screenshot", "BROWSER_FLAGS", "ScreenshotError", "add_parser", "main", "NO_BROWSER_EXIT"]

#: exit status of ``stationbed screenshot`` when no browser is installed (nothing was made: the
#: same status as a viewer that is missing in ``stationbed replay``)
NO_BROWSER_EXIT = 1

#: browsers looked for on PATH, in order (``STATIONBED_CHROMIUM`` overrides)
BROWSER_NAMES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
#: headless, quiet (no network of its own, no first-run, no updates, no sync), software WebGL
BROWSER_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync",
                 "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--hide-scrollbars",
                 "--remote-debugging-pipe")
#: seconds the viewer's page may take to load its wasm bundle and show a canvas
LOAD_TIMEOUT_S = 90.0
#: seconds the capture waits, after the page has loaded, for a still picture
MAX_SETTLE_S = 240.0
#: seconds the viewer server may take to answer on its port
SERVE_TIMEOUT_S = 30.0


class ScreenshotError(RuntimeError):
    """The viewer or the browser did not do their part (one-line reason)."""


def find_browser() -> str | None:
    """The Chromium to use: ``$STATIONBED_CHROMIUM``, else the first of :data:`BROWSER_NAMES` on
    PATH; None when there is none."""
    import shutil

    env = os.environ.get("STATIONBED_CHROMIUM")
    if env:
        return env if shutil.which(env) else None
    for name in BROWSER_NAMES:
        path = shutil.which(name)
        if path:
            return path
    return None


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _wait_http(url: str, timeout: float, proc) -> None:
    import urllib.request

    t_end = time.monotonic() + timeout
    while time.monotonic() < t_end:
        if proc.poll() is not None:
            raise ScreenshotError(f"the viewer server exited with status {proc.returncode} before serving {url}")
        try:
            with urllib.request.urlopen(url, timeout=2.0):
                return
        except OSError:
            time.sleep(0.2)
    raise ScreenshotError(f"the viewer server did not answer on {url} within {timeout:g} s")


class _Pipe:
    """The DevTools protocol over Chromium's ``--remote-debugging-pipe`` (fds 3 in, 4 out)."""

    def __init__(self, write_fd: int, read_fd: int):
        self.w, self.r = write_fd, read_fd
        self.buf = b""
        self.next_id = 0
        self.console: list[str] = []  # the page's console messages and exceptions, in order

    def call(self, method: str, session: str | None = None, timeout: float = 30.0, **params):
        self.next_id += 1
        msg = {"id": self.next_id, "method": method, "params": params}
        if session:
            msg["sessionId"] = session
        os.write(self.w, json.dumps(msg).encode() + b"\0")
        t_end = time.monotonic() + timeout
        while True:
            while b"\0" not in self.buf:
                if time.monotonic() > t_end:
                    raise ScreenshotError(f"the browser did not answer {method} within {timeout:g} s")
                chunk = os.read(self.r, 1 << 20)
                if not chunk:
                    raise ScreenshotError(f"the browser closed its pipe during {method}")
                self.buf += chunk
            raw, self.buf = self.buf.split(b"\0", 1)
            reply = json.loads(raw)
            self._note(reply)
            if reply.get("id") == self.next_id:
                if "error" in reply:
                    raise ScreenshotError(f"{method}: {reply['error'].get('message')}")
                return reply.get("result", {})


    def _note(self, msg) -> None:
        p = msg.get("params", {})
        if msg.get("method") == "Runtime.consoleAPICalled":
            self.console.append(" ".join(str(a.get("value", a.get("description", ""))) for a in p.get("args", [])))
        elif msg.get("method") == "Runtime.exceptionThrown":
            self.console.append(str(p.get("exceptionDetails", {}).get("text")))


#: true once the viewer shows its canvas and no loading screen (the page's own text)
_READY_JS = ("(() => { const c = document.querySelector('canvas');"
             " const t = document.body ? document.body.innerText : '';"
             " return !!c && c.width > 0 && !/Loading/.test(t); })()")


def screenshot(rrd, out, *, width: int = 1600, height: int = 1000, settle_s: float = 6.0,
               browser: str | None = None, rerun_bin: str | None = None) -> Path:
    """Render ``rrd`` in the rerun web viewer in headless Chromium and write the PNG ``out``.

    Parameters
    ----------
    rrd : str or Path
        A rerun recording.
    out : str or Path
        The PNG to write (parent folders are created).
    width, height : int
        Browser window [px]: the viewer's "default window" of the README's images.
    settle_s : float
        Seconds between captures once the loading screen has gone; the PNG is the first capture
        equal to the one before it (the file taken in, plots laid out), at most
        :data:`MAX_SETTLE_S` later.
    browser : str, optional
        Chromium executable (default :func:`find_browser`).
    rerun_bin : str, optional
        The rerun viewer binary (default: ``$STATIONBED_RERUN`` or the one next to the Python).

    Returns
    -------
    Path
        ``out``.

    Raises
    ------
    ScreenshotError
        No browser, the viewer did not serve or the page did not load in time.
    """
    browser = browser or find_browser()
    if browser is None:
        raise ScreenshotError("no Chromium found (install the 'chromium' package: make screenshots does; "
                              "or set STATIONBED_CHROMIUM)")
    import base64
    import shutil
    import subprocess
    import sys
    import tempfile
    import urllib.parse

    rerun_bin = rerun_bin or os.environ.get("STATIONBED_RERUN") or str(Path(sys.executable).with_name("rerun"))
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    files = _serve_file(Path(rrd))  # the web viewer fetches the file itself (CORS-enabled server)
    web = _free_port()
    rrd_url = f"http://127.0.0.1:{files.server_port}/{urllib.parse.quote(Path(rrd).name)}"
    server = subprocess.Popen([rerun_bin, "--web-viewer", "--bind", "127.0.0.1", "--port", str(_free_port()),
                               "--web-viewer-port", str(web), "--renderer", "webgl", rrd_url],
                              stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                              env={**os.environ, "BROWSER": "true"},  # serve only: open no browser of its own
                              start_new_session=True)  # .venv/bin/rerun is a wrapper: stop its whole group
    profile = tempfile.mkdtemp(prefix="stationbed-chromium-")
    chrome = None
    ours = []  # this process's ends of the DevTools pipes
    try:
        _wait_http(f"http://127.0.0.1:{web}/", SERVE_TIMEOUT_S, server)
        url = f"http://127.0.0.1:{web}/?url={urllib.parse.quote(rrd_url, safe='')}&renderer=webgl"
        to_chrome_r, to_chrome_w = os.pipe()
        from_chrome_r, from_chrome_w = os.pipe()
        ours += [to_chrome_w, from_chrome_r]

        def fds():  # the child's fd 3 reads commands, fd 4 writes replies
            os.dup2(to_chrome_r, 3)
            os.dup2(from_chrome_w, 4)

        chrome = subprocess.Popen([browser, *BROWSER_FLAGS, f"--user-data-dir={profile}",
                                   f"--window-size={width},{height}", "about:blank"],
                                  stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                  preexec_fn=fds, pass_fds=(3, 4), start_new_session=True)  # kept open after fds() made them
        os.close(to_chrome_r)
        os.close(from_chrome_w)
        pipe = _Pipe(to_chrome_w, from_chrome_r)
        page = [t for t in pipe.call("Target.getTargets")["targetInfos"] if t["type"] == "page"]
        target = page[0]["targetId"] if page else pipe.call("Target.createTarget", url="about:blank")["targetId"]
        session = pipe.call("Target.attachToTarget", targetId=target, flatten=True)["sessionId"]
        pipe.call("Emulation.setDeviceMetricsOverride", session, width=width, height=height, deviceScaleFactor=1,
                  mobile=False)
        pipe.call("Page.enable", session)
        pipe.call("Runtime.enable", session)
        pipe.call("Page.navigate", session, url=url)
        t_end = time.monotonic() + LOAD_TIMEOUT_S
        while True:
            ready = pipe.call("Runtime.evaluate", session, expression=_READY_JS, returnByValue=True)
            if ready.get("result", {}).get("value") is True:
                break
            if time.monotonic() > t_end:
                raise ScreenshotError(f"the web viewer did not show {rrd} within {LOAD_TIMEOUT_S:g} s")
            time.sleep(0.5)
        # the software-rendered viewer takes its time to take in the file: capture until two frames
        # settle_s apart are the same picture (playback is paused: a still picture is a loaded one)
        t_end = time.monotonic() + LOAD_TIMEOUT_S + MAX_SETTLE_S
        png = None
        while True:
            time.sleep(settle_s)
            shot = pipe.call("Page.captureScreenshot", session, format="png", timeout=60.0)["data"]
            if shot == png or time.monotonic() > t_end:
                break
            png = shot
        out.write_bytes(base64.b64decode(shot))
        if os.environ.get("STATIONBED_SCREENSHOT_DEBUG"):
            print("\n".join(pipe.console))
        return out
    finally:
        for p in (chrome, server):  # each in a session of its own: its group is what it started
            if p is not None:
                _stop_group(p)
        for fd in ours:
            os.close(fd)
        files.shutdown()
        files.server_close()
        shutil.rmtree(profile, ignore_errors=True)


def _stop_group(proc) -> None:
    """Stop ``proc`` and the processes it started (its own process group): SIGTERM, a wait, then
    SIGKILL to whatever of the group is left."""
    import signal
    import subprocess

    try:
        os.killpg(proc.pid, signal.SIGTERM)
    except ProcessLookupError:
        return
    try:
        proc.wait(timeout=10)
    except subprocess.TimeoutExpired:
        pass
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    proc.wait()


def _serve_file(path: Path):
    """A thread serving ``path``'s folder on 127.0.0.1 (a free port), with CORS for the viewer."""
    import functools
    import http.server
    import threading

    class Handler(http.server.SimpleHTTPRequestHandler):
        def end_headers(self):
            self.send_header("Access-Control-Allow-Origin", "*")
            super().end_headers()

        def log_message(self, *args):  # quiet
            pass

    httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0),
                                            functools.partial(Handler, directory=str(path.resolve().parent)))
    threading.Thread(target=httpd.serve_forever, daemon=True).start()
    return httpd


def add_parser(sub) -> None:
    """``stationbed screenshot REC.rrd --out PNG [--width W --height H]``."""
    p = sub.add_parser("screenshot", help="render a recording in the rerun web viewer (headless Chromium) to a PNG")
    p.add_argument("file", type=Path, help="a .rrd recording (stationbed run --rrd, montecarlo.rrd)")
    p.add_argument("--out", type=Path, required=True, help="the PNG to write")
    p.add_argument("--width", type=int, default=1600, help="browser window width [px] (default 1600)")
    p.add_argument("--height", type=int, default=1000, help="browser window height [px] (default 1000)")


def main(args) -> int:
    """Run ``stationbed screenshot``: 0 written, 1 no browser or the viewer failed, 2 bad input."""
    import sys

    def fail(msg, code):
        print(f"stationbed: error: {msg}", file=sys.stderr)
        return code

    f = args.file
    if not f.is_file():
        return fail(f"no recording at {f}", 2)
    with open(f, "rb") as fh:
        if fh.read(3) != b"RRF":
            return fail(f"{f} is not a rerun recording (.rrd)", 2)
    if args.out.suffix.lower() != ".png":
        return fail(f"--out {args.out}: the screenshot is a PNG (name it .png)", 2)
    if args.width < 320 or args.height < 240:
        return fail(f"--width {args.width} --height {args.height}: the viewer needs at least 320 x 240 px", 2)
    if find_browser() is None:
        return fail("no Chromium found, so no screenshot: install the 'chromium' package (make screenshots "
                    "does: apt-get install chromium) or set STATIONBED_CHROMIUM", NO_BROWSER_EXIT)
    try:
        out = screenshot(f, args.out, width=args.width, height=args.height)
    except ScreenshotError as e:
        return fail(str(e), 1)
    print(f"wrote {out}")
    return 0
