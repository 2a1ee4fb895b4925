"""A headless Chromium driven over the DevTools protocol, offline: replay pages are opened from
``file://`` URLs, their JavaScript errors collected, and screenshots taken (``accd-gym replay
--screenshot`` and the browser tests).

The protocol runs over a pipe (``--remote-debugging-pipe``: the browser reads commands from file
descriptor 3 and writes replies and events to 4, each a JSON message ending in a NUL byte), so
no port is opened and no websocket package is needed. Networking is off three ways: the page's
network is emulated offline, every host name resolves to nothing and a dead proxy is set; every
request the page makes is recorded (:attr:`Page.requests`) so a caller can check that none left
the file.

The browser is Debian's ``chromium`` (``apt-get install chromium``) or the one named by the
environment variable ``ACCD_CHROMIUM``. WebGL runs on SwiftShader, Chromium's software renderer.
"""

from __future__ import annotations

import base64
import json
import os
import shutil
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Any, Optional

from accd_gym.errors import AccdError
from accd_gym import files

#: Where a browser is looked for, in order (after ``ACCD_CHROMIUM``).
CANDIDATES = ("/usr/lib/chromium/chromium", "chromium", "chromium-browser", "google-chrome", "google-chrome-stable")


class BrowserError(AccdError, RuntimeError):
    """The browser is missing, failed to start, or a protocol command failed or timed out (an
    :class:`~accd_gym.AccdError`: the command line reports it in one line, exit status 2)."""


def find_chromium() -> Optional[str]:
    """The path of a Chromium executable, or None."""
    env = os.environ.get("ACCD_CHROMIUM")
    if env:
        return env if Path(env).is_file() else shutil.which(env)
    for name in CANDIDATES:
        path = name if os.path.isabs(name) and os.access(name, os.X_OK) else shutil.which(name)
        if path:
            return path
    return None


def _high_pipe() -> tuple[int, int]:
    """A pipe whose two ends are numbered 10 or above (close-on-exec), so that the child can
    duplicate them onto 3 and 4 without overwriting either."""
    import fcntl

    r, w = os.pipe()
    hr, hw = fcntl.fcntl(r, fcntl.F_DUPFD_CLOEXEC, 10), fcntl.fcntl(w, fcntl.F_DUPFD_CLOEXEC, 10)
    os.close(r)
    os.close(w)
    return hr, hw


class Browser:
    """One headless Chromium process (a context manager); :meth:`open` loads a page.

    ``width`` x ``height`` is the window (and screenshot) size in CSS pixels; ``timeout`` the
    longest wait for one protocol reply, s.
    """

    def __init__(self, width: int = 1400, height: int = 900, timeout: float = 60.0, executable: Optional[str] = None) -> None:
        path = executable or find_chromium()
        if path is None:
            raise BrowserError("no Chromium found: install Debian's chromium (apt-get install chromium) or set ACCD_CHROMIUM")
        self.timeout = timeout
        self._profile = tempfile.TemporaryDirectory(prefix="accd-chromium-")
        to_browser_r, self._to_browser = _high_pipe()
        self._from_browser, from_browser_w = _high_pipe()
        args = [
            path,
            "--headless=new",
            "--remote-debugging-pipe",
            f"--user-data-dir={self._profile.name}",
            f"--window-size={int(width)},{int(height)}",
            "--no-first-run",
            "--no-default-browser-check",
            "--disable-extensions",
            "--disable-sync",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-default-apps",
            "--disable-domain-reliability",
            "--no-pings",
            "--host-resolver-rules=MAP * ~NOTFOUND",
            "--proxy-server=http://127.0.0.1:9",
            "--use-angle=swiftshader",
            "--enable-unsafe-swiftshader",
            "--ignore-gpu-blocklist",
            "--hide-scrollbars",
            "--mute-audio",
        ]
        if hasattr(os, "geteuid") and os.geteuid() == 0:
            args.append("--no-sandbox")  # Chromium refuses to run as root with its sandbox
        args.append("about:blank")

        def child_fds() -> None:
            os.dup2(to_browser_r, 3)
            os.dup2(from_browser_w, 4)

        self._log = tempfile.TemporaryFile()
        # The pipe ends are duplicated onto 3 and 4 in the child (inheritable); every other
        # descriptor of this process is close-on-exec (PEP 446), so close_fds is not needed.
        self._proc = subprocess.Popen(args, stdin=subprocess.DEVNULL, stdout=self._log, stderr=self._log,
                                      close_fds=False, preexec_fn=child_fds)
        os.close(to_browser_r)
        os.close(from_browser_w)
        self._buffer = b""
        self._next_id = 0
        self._events: list[dict[str, Any]] = []

    def __enter__(self) -> "Browser":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def close(self) -> None:
        """Ends the browser process and removes its profile."""
        if self._proc.poll() is None:
            try:
                self.send("Browser.close", timeout=5.0)
            except BrowserError:
                pass
            try:
                self._proc.wait(timeout=5.0)
            except subprocess.TimeoutExpired:
                self._proc.kill()
                self._proc.wait()
        for fd in (self._to_browser, self._from_browser):
            try:
                os.close(fd)
            except OSError:
                pass
        self._log.close()
        self._profile.cleanup()

    def log(self) -> str:
        """What the browser printed (stdout and stderr)."""
        self._log.seek(0)
        return self._log.read().decode(errors="replace")

    def _read_message(self, deadline: float) -> dict[str, Any]:
        import select

        while b"\0" not in self._buffer:
            left = deadline - time.monotonic()
            if left <= 0:
                raise BrowserError("timed out waiting for the browser")
            ready, _, _ = select.select([self._from_browser], [], [], min(left, 0.5))
            if not ready:
                if self._proc.poll() is not None:
                    raise BrowserError(f"the browser exited with status {self._proc.returncode}: {self.log()[-2000:]}")
                continue
            chunk = os.read(self._from_browser, 1 << 20)
            if not chunk:
                raise BrowserError(f"the browser closed its pipe: {self.log()[-2000:]}")
            self._buffer += chunk
        raw, self._buffer = self._buffer.split(b"\0", 1)
        return json.loads(raw)

    def send(self, method: str, params: Optional[dict[str, Any]] = None, session: Optional[str] = None,
             timeout: Optional[float] = None) -> dict[str, Any]:
        """Sends one protocol command and returns its result; events that arrive meanwhile are kept."""
        self._next_id += 1
        msg: dict[str, Any] = {"id": self._next_id, "method": method, "params": params or {}}
        if session is not None:
            msg["sessionId"] = session
        os.write(self._to_browser, json.dumps(msg).encode() + b"\0")
        deadline = time.monotonic() + (self.timeout if timeout is None else timeout)
        while True:
            reply = self._read_message(deadline)
            if reply.get("id") == self._next_id:
                if "error" in reply:
                    raise BrowserError(f"{method}: {reply['error']}")
                return reply.get("result", {})
            self._events.append(reply)

    def drain(self, seconds: float = 0.0) -> None:
        """Collects the events that arrive within ``seconds``."""
        deadline = time.monotonic() + seconds
        while True:
            try:
                self._events.append(self._read_message(deadline))
            except BrowserError:
                if self._proc.poll() is not None:
                    raise
                return

    def open(self, url: str, ready: str = "document.readyState === 'complete'", timeout: float = 60.0) -> "Page":
        """Opens ``url`` in a new tab with the network offline and waits until the JavaScript
        expression ``ready`` is true."""
        target = self.send("Target.createTarget", {"url": "about:blank"})["targetId"]
        session = self.send("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]
        page = Page(self, session)
        for domain in ("Runtime", "Log", "Network", "Page"):
            self.send(f"{domain}.enable", session=session)
        self.send("Network.emulateNetworkConditions",
                  {"offline": True, "latency": 0, "downloadThroughput": 0, "uploadThroughput": 0}, session=session)
        self.send("Page.navigate", {"url": url}, session=session)
        page.wait_for(ready, timeout=timeout)
        return page


class Page:
    """A tab of a :class:`Browser`: evaluate JavaScript, take screenshots, read errors and requests."""

    def __init__(self, browser: Browser, session: str) -> None:
        self.browser = browser
        self.session = session

    def evaluate(self, expression: str, await_promise: bool = True) -> Any:
        """The value of a JavaScript expression (promises awaited); raises BrowserError if it throws."""
        result = self.browser.send("Runtime.evaluate", {"expression": expression, "returnByValue": True,
                                                        "awaitPromise": await_promise}, session=self.session)
        if "exceptionDetails" in result:
            raise BrowserError(f"{expression!r} threw: {result['exceptionDetails']}")
        return result["result"].get("value")

    def wait_for(self, expression: str, timeout: float = 60.0) -> None:
        """Waits until ``expression`` is true."""
        deadline = time.monotonic() + timeout
        while True:
            try:
                if self.evaluate(f"Boolean({expression})"):
                    return
            except BrowserError:
                pass
            if time.monotonic() > deadline:
                raise BrowserError(f"timed out waiting for {expression!r}; errors: {self.errors()}")
            time.sleep(0.1)

    def screenshot(self) -> bytes:
        """A PNG of the viewport."""
        data = self.browser.send("Page.captureScreenshot", {"format": "png"}, session=self.session)["data"]
        return base64.b64decode(data)

    def _events(self) -> list[dict[str, Any]]:
        self.browser.drain(0.05)
        return [e for e in self.browser._events if e.get("sessionId") == self.session]

    def errors(self) -> list[str]:
        """Uncaught exceptions, ``console.error`` calls and error log entries of the page."""
        out = []
        for e in self._events():
            method, params = e.get("method"), e.get("params", {})
            if method == "Runtime.exceptionThrown":
                d = params.get("exceptionDetails", {})
                out.append(f"exception: {d.get('exception', {}).get('description') or d.get('text')}")
            elif method == "Runtime.consoleAPICalled" and params.get("type") in ("error", "assert"):
                out.append("console.error: " + " ".join(str(a.get("value", a.get("description", ""))) for a in params.get("args", [])))
            elif method == "Log.entryAdded" and params.get("entry", {}).get("level") == "error":
                out.append(f"log: {params['entry'].get('text')} ({params['entry'].get('url', '')})")
        return out

    def requests(self) -> list[str]:
        """URLs of every request the page made."""
        return [e["params"]["request"]["url"] for e in self._events() if e.get("method") == "Network.requestWillBeSent"]


def screenshot(html: str | Path, png: str | Path, *, setup: Optional[str] = None, width: int = 1400,
               height: int = 900, ready: str = "window.accdReplay && window.accdReplay.ready") -> list[str]:
    """Opens the page ``html`` offline, runs the JavaScript ``setup`` (e.g.
    ``accdReplay.setTime(12.3)``), writes a screenshot to ``png`` and returns the page's errors."""
    url = Path(html).resolve().as_uri()
    with Browser(width, height) as b:
        page = b.open(url, ready=ready)
        if setup:
            page.evaluate(f"Promise.resolve({setup}).then(() => window.accdReplay ? accdReplay.idle() : null)")
        page.evaluate("new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))")

        files.write_bytes(png, page.screenshot())
        return page.errors()


__all__ = ["Browser", "BrowserError", "CANDIDATES", "Page", "find_chromium", "screenshot"]
