"""A headless Chromium driven by Selenium, offline: replay pages are opened from ``file://`` URLs,
their JavaScript errors collected, and screenshots taken (``accd-gym replay --screenshot`` and the
browser tests).

The browser is Debian's ``chromium`` with its ``chromium-driver`` (``apt-get install chromium
chromium-driver``), or the ones named by the environment variables ``ACCD_CHROMIUM`` and
``ACCD_CHROMEDRIVER``; Selenium (``pip install 'accd-gym[replay]'``) talks to the driver, and is
given both paths, so it downloads nothing. Networking is off three ways: the page's network is
emulated offline, every host name resolves to nothing and a dead proxy is set; every request the
page makes is recorded (:meth:`Page.requests`, from the driver's performance log) so a caller can
check that none left the file. WebGL runs on SwiftShader, Chromium's software renderer.
"""

from __future__ import annotations

import json
import os
import shutil
import time
from pathlib import Path
from typing import Any, Optional

from accd_gym import files
from accd_gym.errors import AccdError

#: Where a browser is looked for, in order (after ``ACCD_CHROMIUM``).
CANDIDATES = ("/usr/lib/chromium/chromium", "chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
#: Where its driver is looked for, in order (after ``ACCD_CHROMEDRIVER``).
DRIVER_CANDIDATES = ("/usr/lib/chromium/chromedriver", "chromedriver")


class BrowserError(AccdError, RuntimeError):
    """The browser or its driver is missing, failed to start, or a command failed or timed out (an
    :class:`~accd_gym.AccdError`: the command line reports it in one line, exit status 2)."""


def _find(variable: str, candidates: tuple[str, ...]) -> Optional[str]:
    """The executable named by the environment variable ``variable``, else the first of ``candidates`` found."""
    env = os.environ.get(variable)
    if env:
        return env if Path(env).is_file() else shutil.which(env)
    for name in candidates:
        path = name if os.path.isabs(name) and os.access(name, os.X_OK) else shutil.which(name)
        if path:
            return path
    return None


def find_chromium() -> Optional[str]:
    """The path of a Chromium executable, or None."""
    return _find("ACCD_CHROMIUM", CANDIDATES)


def find_chromedriver() -> Optional[str]:
    """The path of a ChromeDriver executable, or None."""
    return _find("ACCD_CHROMEDRIVER", DRIVER_CANDIDATES)


def available() -> Optional[str]:
    """None when a browser can be started here, else why not (for a test's skip reason)."""
    try:
        import selenium  # noqa: F401
    except ModuleNotFoundError:
        return "Selenium is not installed (pip install 'accd-gym[replay]')"
    if find_chromium() is None:
        return "no Chromium found (apt-get install chromium, or set ACCD_CHROMIUM)"
    if find_chromedriver() is None:
        return "no ChromeDriver found (apt-get install chromium-driver, or set ACCD_CHROMEDRIVER)"
    return None


class Browser:
    """One headless Chromium under its driver (a context manager); :meth:`open` loads a page.

    ``width`` x ``height`` is the window (and screenshot) size in CSS pixels; ``timeout`` the
    longest wait for one command, s.
    """

    def __init__(self, width: int = 1400, height: int = 900, timeout: float = 60.0, executable: Optional[str] = None) -> None:
        why = available() if executable is None else None
        if why is not None:
            raise BrowserError(why)
        from selenium import webdriver
        from selenium.common.exceptions import WebDriverException
        from selenium.webdriver.chrome.service import Service

        options = webdriver.ChromeOptions()
        options.binary_location = executable or find_chromium() or ""
        for arg in ("--headless=new", f"--window-size={int(width)},{int(height)}", "--no-first-run",
                    "--no-default-browser-check", "--disable-extensions", "--disable-sync",
                    "--disable-background-networking", "--disable-component-update", "--disable-default-apps",
                    "--disable-domain-reliability", "--no-pings", "--host-resolver-rules=MAP * ~NOTFOUND",
                    "--proxy-server=http://127.0.0.1:9", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
                    "--ignore-gpu-blocklist", "--hide-scrollbars", "--mute-audio"):
            options.add_argument(arg)
        if hasattr(os, "geteuid") and os.geteuid() == 0:
            options.add_argument("--no-sandbox")  # Chromium refuses to run as root with its sandbox
        options.set_capability("goog:loggingPrefs", {"browser": "ALL", "performance": "ALL"})
        self.timeout = timeout
        try:
            self.driver = webdriver.Chrome(options=options, service=Service(executable_path=find_chromedriver()))
        except WebDriverException as e:
            raise BrowserError(f"the browser failed to start: {e.msg}") from None
        self.driver.set_script_timeout(timeout)
        self.driver.set_page_load_timeout(timeout)
        self._pages = 0

    def __enter__(self) -> "Browser":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def close(self) -> None:
        """Ends the browser and its driver."""
        self.driver.quit()

    def cdp(self, method: str, params: Optional[dict[str, Any]] = None) -> dict[str, Any]:
        """One DevTools protocol command on the current tab (through the driver); its result."""
        from selenium.common.exceptions import WebDriverException

        try:
            return self.driver.execute_cdp_cmd(method, params or {})
        except WebDriverException as e:
            raise BrowserError(f"{method}: {e.msg}") from None

    def open(self, url: str, ready: str = "document.readyState === 'complete'", timeout: float = 60.0) -> "Page":
        """Opens ``url`` in a new tab with the network offline and waits until the JavaScript
        expression ``ready`` is true."""
        if self._pages:
            self.driver.switch_to.new_window("tab")
        self._pages += 1
        page = Page(self)
        page.drain()  # what earlier tabs left in the logs is not this page's
        self.cdp("Network.enable")
        self.cdp("Network.emulateNetworkConditions",
                 {"offline": True, "latency": 0, "downloadThroughput": 0, "uploadThroughput": 0})
        self.driver.get(url)
        page.wait_for(ready, timeout=timeout)
        return page


class Page:
    """The current tab of a :class:`Browser`: evaluate JavaScript, take screenshots, read errors
    and requests."""

    def __init__(self, browser: Browser) -> None:
        self.browser = browser
        self._errors: list[str] = []
        self._requests: list[str] = []

    def evaluate(self, expression: str, await_promise: bool = True) -> Any:
        """The value of a JavaScript expression (promises awaited); raises BrowserError if it throws."""
        result = self.browser.cdp("Runtime.evaluate", {"expression": expression, "returnByValue": True,
                                                       "awaitPromise": await_promise})
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
        return self.browser.driver.get_screenshot_as_png()

    def drain(self) -> None:
        """Moves what the driver logged since the last call into this page's errors and requests."""
        driver = self.browser.driver
        for entry in driver.get_log("browser"):
            if entry.get("level") == "SEVERE":
                self._errors.append(str(entry.get("message")))
        for entry in driver.get_log("performance"):
            message = json.loads(entry["message"]).get("message", {})
            if message.get("method") == "Network.requestWillBeSent":
                self._requests.append(message["params"]["request"]["url"])

    def errors(self) -> list[str]:
        """Uncaught exceptions, ``console.error`` calls and error log entries of the page."""
        self.drain()
        return list(self._errors)

    def requests(self) -> list[str]:
        """URLs of every request the page made."""
        self.drain()
        return list(self._requests)


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


__all__ = ["Browser", "BrowserError", "CANDIDATES", "DRIVER_CANDIDATES", "Page", "available", "find_chromedriver",
           "find_chromium", "screenshot"]
