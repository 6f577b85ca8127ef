"""Headless Chromium (Debian's package) driven over the DevTools Protocol, for the browser tests.

A small synchronous CDP client over ``websockets`` (a dependency already): one
browser process, pages as targets attached in flattened session mode, commands
answered by id on a reader thread, events kept for the tests (console errors,
uncaught exceptions, the requests a page made). No browser download: the tests
skip, saying why, when ``chromium`` is not installed (``.ci/run`` installs it).

Chromium runs with its own default autoplay policy (the video tests depend on
it) and with every host name but 127.0.0.1/localhost unresolvable, so a page
that reached for the network would fail to load its files.
"""

from __future__ import annotations

import base64
import itertools
import json
import os
import shutil
import subprocess
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from websockets.sync.client import ClientConnection, connect

START_TIMEOUT_S = 30.0
COMMAND_TIMEOUT_S = 30.0

Message = dict[str, Any]


def chromium_path() -> str | None:
    """The Chromium executable (``RWT_CHROMIUM`` or ``chromium`` on PATH), or None."""
    return os.environ.get("RWT_CHROMIUM") or shutil.which("chromium")


class CdpError(RuntimeError):
    """A DevTools command failed, or the page did not get where a test waited for."""


class Browser:
    """One headless Chromium with a DevTools connection; ``close()`` ends it."""

    def __init__(self, executable: str, reachable: tuple[str, ...] = ()) -> None:
        """Start Chromium (``executable``); ``reachable``: addresses besides 127.0.0.1
        and localhost that its resolver leaves alone (a benchmark's robot)."""
        rules = ", ".join(f"EXCLUDE {a}" for a in ("127.0.0.1", "localhost", *reachable))
        self.profile = Path(tempfile.mkdtemp(prefix="rwt-chromium-"))
        self.log = open(self.profile / "stderr.log", "wb")  # noqa: SIM115 - closed in close()
        args = [
            executable,
            "--headless=new",
            "--disable-gpu",
            "--window-size=1280,900",  # a desktop's; the responsive test emulates others
            "--disable-dev-shm-usage",
            "--no-first-run",
            "--no-default-browser-check",
            "--disable-extensions",
            "--disable-background-networking",
            "--disable-component-update",
            "--remote-debugging-port=0",
            f"--host-resolver-rules=MAP * ~NOTFOUND, {rules}",
            f"--user-data-dir={self.profile}",
            "about:blank",
        ]
        if os.geteuid() == 0:
            args.insert(1, "--no-sandbox")  # Chromium refuses to run as root with its sandbox
        self.proc = subprocess.Popen(
            args, stdin=subprocess.DEVNULL, stdout=self.log, stderr=self.log
        )
        # entered as a context manager: websockets 17.1 warns about a bare connect()
        # no keepalive pings: each draws from the random module, which a property-based
        # test running meanwhile in this process (the browser lives for the session)
        # sees as a strategy using it; a local pipe to Chromium needs none
        self.ws = connect(
            self._devtools_url(), max_size=None, open_timeout=START_TIMEOUT_S, ping_interval=None
        ).__enter__()
        self._ids = itertools.count(1)
        self._replies: dict[int, Message] = {}
        self._events: list[Message] = []
        self._changed = threading.Condition()
        self.broken: Exception | None = None
        self._reader = threading.Thread(target=self._read, args=(self.ws,), daemon=True)
        self._reader.start()

    def _devtools_url(self) -> str:
        """The browser's DevTools WebSocket, from the DevToolsActivePort file it writes."""
        port_file = self.profile / "DevToolsActivePort"
        deadline = time.monotonic() + START_TIMEOUT_S
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                break
            lines = port_file.read_text().split() if port_file.exists() else []
            if len(lines) >= 2:
                return f"ws://127.0.0.1:{lines[0]}{lines[1]}"
            time.sleep(0.05)
        self.close()
        raise CdpError(f"chromium did not start: {self.stderr()[-2000:]}")

    def stderr(self) -> str:
        """What Chromium logged so far."""
        return (self.profile / "stderr.log").read_text(errors="replace")

    def _read(self, ws: ClientConnection) -> None:
        try:
            for raw in ws:
                message = json.loads(raw)
                with self._changed:
                    if "id" in message:
                        self._replies[message["id"]] = message
                    else:
                        self._events.append(message)
                    self._changed.notify_all()
        except Exception as exc:  # the browser went away: waiters fail with the reason
            with self._changed:
                self.broken = exc
                self._changed.notify_all()

    def send(self, method: str, session: str | None = None, **params: Any) -> Message:
        """Run one DevTools command and return its result.

        Raises:
            CdpError: the command failed or got no answer within ``COMMAND_TIMEOUT_S``.
        """
        command_id = next(self._ids)
        message: Message = {"id": command_id, "method": method, "params": params}
        if session is not None:
            message["sessionId"] = session
        self.ws.send(json.dumps(message))
        deadline = time.monotonic() + COMMAND_TIMEOUT_S
        with self._changed:
            while command_id not in self._replies:
                if self.broken is not None:
                    raise CdpError(f"{method}: the DevTools connection broke: {self.broken!r}")
                left = deadline - time.monotonic()
                if left <= 0:
                    raise CdpError(f"{method}: no answer in {COMMAND_TIMEOUT_S} s")
                self._changed.wait(left)
            reply = self._replies.pop(command_id)
        if "error" in reply:
            raise CdpError(f"{method}: {reply['error']}")
        return reply.get("result", {})

    def events(self, session: str | None, method: str | None = None) -> list[Message]:
        """The events of one page so far (of one ``method`` when given); with ``session``
        None, the browser's own (``Browser.downloadProgress``...)."""
        with self._changed:
            return [
                e
                for e in self._events
                if e.get("sessionId") == session and (method is None or e["method"] == method)
            ]

    def new_page(self) -> Page:
        """A new tab, attached, with Runtime, Log, Page and Network events on."""
        target = self.send("Target.createTarget", url="about:blank")["targetId"]
        session = self.send("Target.attachToTarget", targetId=target, flatten=True)["sessionId"]
        page = Page(self, target, session)
        for domain in ("Runtime", "Log", "Page", "Network"):
            self.send(f"{domain}.enable", session)
        return page

    def close(self) -> None:
        """End the browser and remove its profile."""
        if hasattr(self, "ws"):
            self.ws.close()
        self.proc.terminate()
        try:
            self.proc.wait(10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(10)
        self.log.close()
        # Chromium's helper processes may still write a file or two as they exit
        deadline = time.monotonic() + 5
        while self.profile.exists() and time.monotonic() < deadline:
            shutil.rmtree(self.profile, ignore_errors=True)
            time.sleep(0.1)


class Page:
    """One tab: navigate, evaluate JavaScript, wait for a condition, take screenshots."""

    def __init__(self, browser: Browser, target: str, session: str) -> None:
        self.browser = browser
        self.target = target
        self.session = session

    def send(self, method: str, **params: Any) -> Message:
        """A DevTools command on this page."""
        return self.browser.send(method, self.session, **params)

    def goto(self, url: str, timeout_s: float = 20.0) -> None:
        """Open ``url`` and wait until its document (and its module scripts) loaded."""
        result = self.send("Page.navigate", url=url)
        if result.get("errorText"):
            raise CdpError(f"cannot open {url}: {result['errorText']}")
        self.wait_for("document.readyState === 'complete'", timeout_s, f"{url} to load")

    def evaluate(self, expression: str) -> Any:
        """The value of a JavaScript expression (promises awaited), as JSON.

        Raises:
            CdpError: the expression threw.
        """
        result = self.send(
            "Runtime.evaluate", expression=expression, awaitPromise=True, returnByValue=True
        )
        if "exceptionDetails" in result:
            details = result["exceptionDetails"]
            text = details.get("exception", {}).get("description") or details.get("text")
            raise CdpError(f"{expression!r} threw: {text}")
        return result["result"].get("value")

    def wait_for(self, expression: str, timeout_s: float = 15.0, what: str = "") -> Any:
        """Poll ``expression`` until it is truthy; return its value.

        Raises:
            CdpError: still falsy after ``timeout_s`` (with the page's errors so far).
        """
        deadline = time.monotonic() + timeout_s
        while True:
            value = self.evaluate(expression)
            if value:
                return value
            if time.monotonic() > deadline:
                raise CdpError(
                    f"waited {timeout_s} s for {what or expression}; page errors: {self.errors()}"
                )
            time.sleep(0.1)

    def click(self, selector: str) -> None:
        """Click the first element matching ``selector`` (as a user's click would)."""
        self.wait_for(f"!!document.querySelector({json.dumps(selector)})", what=selector)
        self.evaluate(f"document.querySelector({json.dumps(selector)}).click()")

    def fill(self, selector: str, value: str) -> None:
        """Type ``value`` into an input, firing ``input`` like a user would."""
        self.wait_for(f"!!document.querySelector({json.dumps(selector)})", what=selector)
        self.evaluate(
            f"(() => {{ const e = document.querySelector({json.dumps(selector)});"
            f" e.value = {json.dumps(value)};"
            " e.dispatchEvent(new Event('input', {bubbles: true})); })()"
        )

    def key(self, kind: str, key: str, code: int) -> None:
        """One key event (``keyDown`` or ``keyUp``) of ``key`` on the focused element."""
        self.send(
            "Input.dispatchKeyEvent",
            type=kind,
            key=key,
            code=f"Key{key.upper()}" if len(key) == 1 else key,
            windowsVirtualKeyCode=code,
        )

    def press(self, key: str, code: int) -> None:
        """Press and release ``key`` (``Enter``, ``ArrowRight``...; ``code`` its key code)
        on the focused element, through Chromium's input pipeline as a keyboard would."""
        text = {"Enter": "\r", " ": " "}.get(key)
        for kind in ("keyDown", "keyUp"):
            params: dict[str, Any] = {
                "type": kind,
                "key": key,
                "code": "Space" if key == " " else key,
                "windowsVirtualKeyCode": code,
            }
            if kind == "keyDown" and text:
                params["text"] = text
            self.send("Input.dispatchKeyEvent", **params)

    def text(self, selector: str) -> str:
        """The text of the first element matching ``selector`` ('' when there is none)."""
        found = self.evaluate(f"document.querySelector({json.dumps(selector)})?.textContent ?? ''")
        return str(found)

    def screenshot(self, selector: str) -> bytes:
        """A PNG of the element matching ``selector``, at its size on the page."""
        box = self.evaluate(
            f"(() => {{ const e = document.querySelector({json.dumps(selector)});"
            " e.scrollIntoView(); const r = e.getBoundingClientRect();"
            " return [r.x + scrollX, r.y + scrollY, r.width, r.height]; })()"
        )
        x, y, width, height = box
        clip = {"x": x, "y": y, "width": width, "height": height, "scale": 1}
        data = self.send(
            "Page.captureScreenshot", format="png", clip=clip, captureBeyondViewport=True
        )["data"]
        return base64.b64decode(data)

    def viewport_png(self) -> bytes:
        """A PNG of what the window shows, at its size (the emulated one, if any)."""
        return base64.b64decode(self.send("Page.captureScreenshot", format="png")["data"])

    def errors(self) -> list[str]:
        """Uncaught exceptions, console.error calls and error log entries of this page."""
        found: list[str] = []
        for event in self.browser.events(self.session):
            params = event.get("params", {})
            if event["method"] == "Runtime.exceptionThrown":
                details = params["exceptionDetails"]
                found.append(details.get("exception", {}).get("description") or details["text"])
            elif event["method"] == "Runtime.consoleAPICalled" and params["type"] == "error":
                args = params["args"]
                found.append(" ".join(str(a.get("value", a.get("description"))) for a in args))
            elif event["method"] == "Log.entryAdded" and params["entry"]["level"] == "error":
                found.append(f"{params['entry'].get('url', '')}: {params['entry']['text']}")
        return found

    def requested_urls(self) -> list[str]:
        """Every URL this page asked for (documents, scripts, styles, XHR, WebSockets, media)."""
        requests = self.browser.events(self.session, "Network.requestWillBeSent")
        sockets = self.browser.events(self.session, "Network.webSocketCreated")
        return [e["params"]["request"]["url"] for e in requests] + [
            e["params"]["url"] for e in sockets
        ]

    def close(self) -> None:
        """Close the tab."""
        self.browser.send("Target.closeTarget", targetId=self.target)


def wait_until(check: Callable[[], Any], timeout_s: float, what: str) -> Any:
    """Poll ``check`` (Python side) until truthy; CdpError after ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while True:
        value = check()
        if value:
            return value
        if time.monotonic() > deadline:
            raise CdpError(f"waited {timeout_s} s for {what}")
        time.sleep(0.05)
