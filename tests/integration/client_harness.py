"""Start `rwt serve` and drive real rosbridge clients (roslibpy, roslib in Node) against it.

A scenario is a list of phases, each `(role, steps)`. The steps of a role use a
connection named after the role. When both roles use the same client library the
phases run in one driver process, in order; when they differ (cross-client) each
role gets its own process, and the harness hands over between phases: the role
that finishes a phase prints a `signal`, the role whose phase comes next was
blocked on an `await` and gets a line on stdin. The step format is documented in
roslibpy_driver.py.

Every wait here is bounded; a failure message carries the drivers' stderr.
"""

from __future__ import annotations

import contextlib
import json
import os
import queue
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tests.support.cli import RWT, RWT_COLD
from tests.support.warm import PYTHON, rwt_env

HERE = Path(__file__).resolve().parent
REPO = HERE.parent.parent
JS_DIR = REPO / "tests" / "js"
JS_DRIVER = JS_DIR / "rosclient.mjs"
PY_DRIVER = HERE / "roslibpy_driver.py"
#: A server with in-process services, an action server and an in-process caller.
SERVE_FIXTURE = HERE / "serve_fixture.py"
#: `--interfaces` folder with the test interface package rwt_test_interfaces.
TEST_INTERFACES = HERE / "data"

SERVER_START_TIMEOUT = 20.0
SERVER_STOP_TIMEOUT = 10.0
#: Bound for a driver process to finish once the scenario is under way.
DRIVER_TIMEOUT = 40.0
#: Written into each scenario: a driver gives up on its own before the harness does.
SCENARIO_TIMEOUT_MS = 30000
STEP_TIMEOUT_MS = 10000

CLIENTS = ("roslibpy", "roslibjs")

#: Runs a command (its argv after these) with SIGINT at its default, as a shell starts
#: it (``-S``: this wrapper itself needs no site-packages). A child inherits ignored
#: signals, and pytest started in the background by a non-interactive shell
#: (``python -m pytest &``) ignores SIGINT and SIGQUIT (SigIgn ...006), as do its xdist
#: workers: an example, which stops on Ctrl-C by the KeyboardInterrupt Python raises
#: only when SIGINT was not ignored at its start, would never see the SIGINT
#: ``ServerProcess.stop`` sends, and be killed after ``SERVER_STOP_TIMEOUT`` (each such
#: server's test 10 s longer). ``execvp`` (a PATH lookup, as Popen does) keeps the
#: process (pid, pipes) the command's.
AS_A_SHELL_STARTS_IT = [
    sys.executable,
    "-S",
    "-c",
    "import os, signal, sys; signal.signal(signal.SIGINT, signal.SIG_DFL); "
    "os.execvp(sys.argv[1], sys.argv[1:])",
]


def node_missing_reason() -> str | None:
    """Why the Node client tests cannot run here, or None when they can."""
    if shutil.which("node") is None:
        return "node is not on PATH (CI installs Node 20)"
    if not (JS_DIR / "node_modules" / "roslib").is_dir():
        return "tests/js/node_modules is missing: run `npm ci --prefix tests/js`"
    return None


class _LineReader:
    """Reads a pipe's lines on a thread so that every read can be bounded."""

    def __init__(self, pipe: Any, name: str) -> None:
        self.lines: queue.Queue[str | None] = queue.Queue()
        self.seen: list[str] = []
        self._thread = threading.Thread(target=self._run, args=(pipe,), name=name, daemon=True)
        self._thread.start()

    def _run(self, pipe: Any) -> None:
        with contextlib.suppress(ValueError, OSError):
            for raw in pipe:
                line = raw.decode("utf-8", "replace").rstrip("\r\n")
                self.seen.append(line)
                self.lines.put(line)
        self.lines.put(None)

    def get(self, deadline: float) -> str | None:
        """The next line, None at end of file; raises TimeoutError past `deadline`."""
        left = deadline - time.monotonic()
        if left <= 0:
            raise TimeoutError
        try:
            return self.lines.get(timeout=left)
        except queue.Empty:
            raise TimeoutError from None


def _close_pipes(proc: subprocess.Popen) -> None:
    for pipe in (proc.stdin, proc.stdout):
        if pipe is not None:
            with contextlib.suppress(OSError, ValueError):
                pipe.close()


# --------------------------------------------------------------------------- server
class ServerProcess:
    """`python -m rwt serve --host 127.0.0.1 --port 0` in a subprocess.

    With `control=True` (for serve_fixture.py) the server's stdin is a pipe:
    `command()` writes one JSON line, `replies()` reads the JSON lines it prints.
    """

    def __init__(
        self,
        workdir: Path,
        extra_args: tuple[str, ...] = (),
        cmd: list[str] | None = None,
        *,
        control: bool = False,
        cold: bool = False,
    ) -> None:
        self.stderr_path = workdir / "rwt-serve.stderr"
        self.cmd = cmd or [
            *(RWT_COLD if cold else RWT),
            "serve",
            "--host",
            "127.0.0.1",
            "--port",
            "0",
            *extra_args,
        ]
        self._stderr = open(self.stderr_path, "wb")  # noqa: SIM115 - closed in stop()
        env = rwt_env()  # this checkout's code, not whatever rwt an editable install points at
        self.proc = subprocess.Popen(
            [*AS_A_SHELL_STARTS_IT, *self.cmd],
            stdin=subprocess.PIPE if control else subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=self._stderr,
            cwd=workdir,
            env=env,
        )
        self._stdout = _LineReader(self.proc.stdout, "rwt-serve-stdout")
        self.url = self._read_url()
        self.returncode: int | None = None
        self._replies: dict[str, dict] = {}
        self.reply_order: list[str] = []

    def _read_url(self) -> str:
        deadline = time.monotonic() + SERVER_START_TIMEOUT
        try:
            line = self._stdout.get(deadline)
        except TimeoutError:
            self.stop()
            raise RuntimeError(
                f"`{' '.join(self.cmd)}` printed nothing within {SERVER_START_TIMEOUT:.0f}s\n"
                f"stderr:\n{self.stderr_text()}"
            ) from None
        prefix = "listening on "
        if line is None or not line.startswith(prefix + "ws://"):
            self.stop()
            raise RuntimeError(
                f"`{' '.join(self.cmd)}` first stdout line was {line!r}, expected "
                f"'listening on ws://HOST:PORT' (exit code {self.proc.poll()})\n"
                f"stderr:\n{self.stderr_text()}"
            )
        return line[len(prefix) :].strip()

    @property
    def port(self) -> int:
        return int(self.url.rsplit(":", 1)[1].split("/", 1)[0])

    def next_stdout_line(self, timeout_s: float = SERVER_START_TIMEOUT) -> str | None:
        """The server's next stdout line (``video on http://...`` with ``--video``)."""
        return self._stdout.get(time.monotonic() + timeout_s)

    def stderr_text(self) -> str:
        if not self._stderr.closed:
            self._stderr.flush()
        try:
            return self.stderr_path.read_text("utf-8", "replace")
        except OSError as exc:
            return f"<could not read server stderr: {exc}>"

    def command(self, **command: Any) -> None:
        """Send one command line to serve_fixture.py (see its docstring)."""
        assert self.proc.stdin is not None, "start the server with control=True"
        self.proc.stdin.write(json.dumps(command).encode() + b"\n")
        self.proc.stdin.flush()

    def replies(
        self, names: list[str], timeout_s: float = STEP_TIMEOUT_MS / 1000
    ) -> dict[str, dict]:
        """The replies to the commands sent `as` each of `names`, in any order (bounded)."""
        deadline = time.monotonic() + timeout_s
        while not all(name in self._replies for name in names):
            try:
                line = self._stdout.get(deadline)
            except TimeoutError:
                missing = [n for n in names if n not in self._replies]
                raise DriverError(f"server: no reply for {missing} in {timeout_s:g}s") from None
            if line is None:
                raise DriverError(f"server exited (code {self.proc.poll()}) before replying")
            reply = json.loads(line)
            self._replies[reply["as"]] = reply
            self.reply_order.append(reply["as"])
        return {name: self._replies[name] for name in names}

    def stop(self) -> int | None:
        """SIGINT, then SIGKILL if it does not stop in time. Returns the exit code."""
        if self.proc.stdin is not None:  # serve_fixture.py stops when its stdin closes
            with contextlib.suppress(OSError, ValueError):
                self.proc.stdin.close()
            with contextlib.suppress(subprocess.TimeoutExpired):
                self.proc.wait(SERVER_STOP_TIMEOUT)
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(SERVER_STOP_TIMEOUT)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(SERVER_STOP_TIMEOUT)
        self.returncode = self.proc.returncode
        _close_pipes(self.proc)
        self._stderr.close()
        return self.returncode


# --------------------------------------------------------------------------- drivers
def run_client_script(
    workdir: Path, server_args: tuple[str, ...], script: str
) -> tuple[Any, str, str]:
    """Run a Python client ``script`` (its ``{port}`` filled in) against ``rwt serve ARGS``.

    Returns what the script printed last, as JSON, its stderr (a client's log) and
    the server's log. The server is stopped afterwards whatever happened.
    """
    server = ServerProcess(workdir, server_args)
    try:
        done = subprocess.run(
            [*PYTHON, "-c", script.format(port=server.port)],
            env=rwt_env(),
            capture_output=True,
            text=True,
            timeout=60,
            check=True,
        )
    finally:
        server.stop()
    return json.loads(done.stdout.strip().splitlines()[-1]), done.stderr, server.stderr_text()


class DriverError(AssertionError):
    pass


class Driver:
    """One client process running a list of steps (roslibpy or roslib-in-Node)."""

    def __init__(self, client: str, url: str, steps: list[dict], workdir: Path, label: str) -> None:
        self.client = client
        self.label = label
        scenario = {
            "timeout_ms": SCENARIO_TIMEOUT_MS,
            "step_timeout_ms": STEP_TIMEOUT_MS,
            "steps": steps,
        }
        fd, path = tempfile.mkstemp(prefix=f"{label}-", suffix=".json", dir=workdir)
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            json.dump(scenario, f)
        if client == "roslibpy":
            cmd = [*PYTHON, str(PY_DRIVER), url, path]
            cwd = HERE
        elif client == "roslibjs":
            node = shutil.which("node")
            if node is None:
                raise DriverError(node_missing_reason())
            cmd = [node, str(JS_DRIVER), url, path]
            cwd = JS_DIR
        else:
            raise ValueError(client)
        self.stderr_path = Path(path).with_suffix(".stderr")
        self._stderr = open(self.stderr_path, "wb")  # noqa: SIM115 - closed in kill()
        self.proc = subprocess.Popen(
            cmd,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=self._stderr,
            cwd=cwd,
            env=rwt_env(),
        )
        self._stdout = _LineReader(self.proc.stdout, f"{label}-stdout")
        self.result: dict | None = None

    def describe(self) -> str:
        if not self._stderr.closed:
            self._stderr.flush()
        err = self.stderr_path.read_text("utf-8", "replace")
        out = "\n".join(line[:500] for line in self._stdout.seen)
        return (
            f"--- {self.label} ({self.client}) exit={self.proc.poll()}\n"
            f"stdout:\n{out}\nstderr:\n{err}"
        )

    def _next(self, deadline: float, wanted: str) -> dict:
        while True:
            try:
                line = self._stdout.get(deadline)
            except TimeoutError:
                raise DriverError(f"{self.label}: timed out waiting for {wanted}") from None
            if line is None:
                with contextlib.suppress(subprocess.TimeoutExpired):
                    self.proc.wait(5)
                raise DriverError(f"{self.label}: exited before {wanted}")
            try:
                return json.loads(line)
            except ValueError:
                continue  # not one of ours (a library printing); keep it in the log

    def wait_event(self, name: str, deadline: float) -> None:
        frame = self._next(deadline, f"event {name!r}")
        if frame.get("event") != name:
            raise DriverError(f"{self.label}: expected event {name!r}, got {frame}")

    def go(self) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.write(b"go\n")
        self.proc.stdin.flush()

    def wait_result(self, deadline: float) -> dict:
        frame = self._next(deadline, "its result")
        if "result" not in frame:
            raise DriverError(f"{self.label}: expected the result, got {frame}")
        try:
            code = self.proc.wait(max(0.1, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            raise DriverError(f"{self.label}: printed its result but did not exit") from None
        if code != 0:
            raise DriverError(f"{self.label}: exit code {code} after its result")
        self.result = frame["result"]
        return self.result

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            with contextlib.suppress(subprocess.TimeoutExpired):
                self.proc.wait(5)
        _close_pipes(self.proc)
        self._stderr.close()


@dataclass
class Outcome:
    """What the clients saw, merged over driver processes (and harness phases)."""

    received: dict[str, dict[str, list]] = field(default_factory=dict)
    wire: dict[str, dict[str, list]] = field(default_factory=dict)
    status_count: int = 0
    statuses: list[dict] = field(default_factory=list)
    calls: dict[str, dict] = field(default_factory=dict)
    tf: dict[str, dict[str, list]] = field(default_factory=dict)
    served: dict[str, dict[str, list]] = field(default_factory=dict)
    feedback: dict[str, list] = field(default_factory=dict)
    goal_ids: dict[str, str] = field(default_factory=dict)
    order: dict[str, list[str]] = field(default_factory=dict)

    def add(self, result: dict) -> None:
        self.received.update(result["received"])
        self.wire.update(result["wire"])
        self.status_count += result["status_count"]
        self.statuses.extend(result["statuses"])
        self.calls.update(result.get("calls", {}))
        self.tf.update(result.get("tf", {}))
        self.served.update(result.get("served", {}))
        self.feedback.update(result.get("feedback", {}))
        self.goal_ids.update(result.get("goal_ids", {}))
        self.order.update(result.get("order", {}))

    def ok(self, name: str) -> Any:
        """What the call recorded as `name` returned; fails if it reported an error."""
        outcome = self.calls.get(name)
        assert outcome is not None, f"no call recorded as {name!r}: {self.calls}"
        assert "ok" in outcome, f"{name} failed: {outcome['error']}"
        return outcome["ok"]

    def error(self, name: str) -> Any:
        """What the failure callback of the call recorded as `name` got; fails if it succeeded."""
        outcome = self.calls.get(name)
        assert outcome is not None, f"no call recorded as {name!r}: {self.calls}"
        assert "error" in outcome, f"{name} succeeded with {outcome['ok']!r}"
        return outcome["error"]

    def got(self, conn: str, topic: str) -> list:
        """Messages the user callback of `conn` got on `topic`."""
        return self.received.get(conn, {}).get(topic, [])

    def on_wire(self, conn: str, topic: str) -> list:
        """Every publish frame `conn` got for `topic` (also after unsubscribe)."""
        return self.wire.get(conn, {}).get(topic, [])


#: The role of phases that the harness itself runs (a callable instead of steps).
HARNESS = "harness"


class Running:
    """What a harness phase gets: the outcome so far and the driver processes by role."""

    def __init__(self, outcome: Outcome) -> None:
        self.outcome = outcome
        self.drivers: dict[str, Driver] = {}
        self.killed: set[str] = set()

    def kill(self, role: str) -> None:
        """SIGKILL the process of `role` (its connections drop without a close frame)."""
        self.drivers[role].kill()
        self.killed.add(role)


HarnessStep = Callable[[Running], None]
Phase = tuple[str, list[dict] | HarnessStep]


def _switches(phases: list[Phase]) -> dict[int, str]:
    """Phase index -> the previous phase's role, wherever the role changes."""
    return {i: phases[i - 1][0] for i in range(1, len(phases)) if phases[i - 1][0] != phases[i][0]}


def _role_steps(phases: list[Phase], roles: list[str]) -> dict[str, list[dict]]:
    """Each driver role's steps, with a `signal` where it hands over and an `await`
    where it takes over (a role whose first phase is not the first one starts
    blocked on `await`, so all processes can start, and pay their start-up, at once)."""
    per_role: dict[str, list[dict]] = {r: [] for r in roles}
    switches = _switches(phases)
    for i, (role, steps) in enumerate(phases):
        prev = switches.get(i)
        if prev is not None and prev != HARNESS:
            per_role[prev].append({"op": "signal", "name": f"phase{i}"})
        if prev is not None and role != HARNESS:
            per_role[role].append({"op": "await"})
        if role != HARNESS:
            assert isinstance(steps, list), f"phase {i} of {role} must be a list of steps"
            per_role[role].extend(steps)
    return per_role


def run_scenario(url: str, phases: list[Phase], clients: dict[str, str], workdir: Path) -> Outcome:
    """Run `phases`; `clients` maps each role to "roslibpy" or "roslibjs".

    A phase of role HARNESS is a callable run here, between the drivers' phases
    (an in-process call, killing a role, the Python client...). Without one,
    roles of one client library share one process; otherwise each role has its own.
    """
    roles = list(dict.fromkeys(role for role, _ in phases if role != HARNESS))
    kinds = {clients[r] for r in roles}
    deadline = time.monotonic() + DRIVER_TIMEOUT
    outcome = Outcome()
    running = Running(outcome)
    try:
        if len(kinds) == 1 and all(role != HARNESS for role, _ in phases):
            # one process runs the phases in order: no handovers needed
            steps = [s for _, phase in phases if isinstance(phase, list) for s in phase]
            d = Driver(kinds.pop(), url, steps, workdir, "+".join(roles))
            running.drivers[d.label] = d
            outcome.add(d.wait_result(deadline))
            return outcome

        for role, steps in _role_steps(phases, roles).items():
            running.drivers[role] = Driver(clients[role], url, steps, workdir, role)
        switches = _switches(phases)
        for i, (role, phase) in enumerate(phases):
            prev = switches.get(i)
            if prev is not None and prev != HARNESS:
                running.drivers[prev].wait_event(f"phase{i}", deadline)
            if prev is not None and role != HARNESS:
                running.drivers[role].go()
            if callable(phase):
                phase(running)
        for role, d in running.drivers.items():
            if role not in running.killed:
                outcome.add(d.wait_result(deadline))
        return outcome
    except AssertionError as exc:  # DriverError, or a harness phase's own check
        for d in running.drivers.values():
            if d.proc.poll() is None:
                d.proc.kill()
                with contextlib.suppress(subprocess.TimeoutExpired):
                    d.proc.wait(5)
        details = "\n".join(d.describe() for d in running.drivers.values())
        raise DriverError(f"{exc}\n{details}") from None
    finally:
        for d in running.drivers.values():
            d.kill()


# --------------------------------------------------------------------------- helpers
def connect(role: str) -> dict:
    return {"op": "connect", "conn": role}


def subscribe(role: str, topic: str, msg_type: str | None, compression: str | None = None) -> dict:
    """Subscribe `role` to `topic`; `compression` ("png", "cbor") as its Topic sends it."""
    step = {"op": "subscribe", "conn": role, "topic": topic}
    if msg_type is not None:
        step["type"] = msg_type
    if compression is not None:
        step["compression"] = compression
    return step


def unsubscribe(role: str, topic: str) -> dict:
    return {"op": "unsubscribe", "conn": role, "topic": topic}


def advertise(role: str, topic: str, msg_type: str) -> dict:
    return {"op": "advertise", "conn": role, "topic": topic, "type": msg_type}


def publish(role: str, topic: str, *msgs: Any) -> dict:
    return {"op": "publish", "conn": role, "topic": topic, "msgs": list(msgs)}


def sync(role: str) -> dict:
    """Barrier: everything `role` sent before has been processed by the server."""
    return {"op": "sync", "conn": role}


def wait(role: str, topic: str, count: int) -> dict:
    return {"op": "wait", "conn": role, "topic": topic, "count": count}


def quiet(ms: int) -> dict:
    return {"op": "quiet", "ms": ms}


def close(role: str) -> dict:
    return {"op": "close", "conn": role}


def api(role: str, name: str, call: str, *args: Any, blocking: bool = False) -> dict:
    """Call the client's rosapi helper `call` with `args`; record the outcome as `name`."""
    step = {"op": "api", "conn": role, "as": name, "call": call, "args": list(args)}
    if blocking:
        step["blocking"] = True
    return step


def tf_client(
    role: str,
    name: str,
    client: str,
    frames: list[str],
    *,
    fixed_frame: str = "base_link",
    angular_thres: float = 2.0,
    trans_thres: float = 0.01,
    rate: float = 10.0,
) -> dict:
    """Make the library's TF client `client` subscribed to `frames`, recorded as `name`."""
    return {
        "op": "tf",
        "conn": role,
        "as": name,
        "client": client,
        "frames": frames,
        "fixed_frame": fixed_frame,
        "angular_thres": angular_thres,
        "trans_thres": trans_thres,
        "rate": rate,
    }


def tf_wait(name: str, frame: str, count: int) -> dict:
    return {"op": "tf_wait", "as": name, "frame": frame, "count": count}


def tf_dispose(name: str) -> dict:
    return {"op": "tf_dispose", "as": name}


def advertise_service(role: str, service: str, srv_type: str, reply: str, **options: Any) -> dict:
    """Provide `service`, answering by the rule `reply` (see roslibpy_driver.py)."""
    return {
        "op": "advertise_service",
        "conn": role,
        "service": service,
        "type": srv_type,
        "reply": reply,
        **options,
    }


def call(
    role: str, name: str, service: str, srv_type: str, args: Any = None, *, wait: bool = True
) -> dict:
    """Call `service`; record what the callback or failure callback got as `name`."""
    step = {"op": "call", "conn": role, "as": name, "service": service, "type": srv_type}
    if args is not None:
        step["args"] = args
    if not wait:
        step["wait"] = False
    return step


def wait_calls(*names: str) -> dict:
    """Wait until the calls or goals recorded as `names` ended."""
    return {"op": "wait_calls", "as": list(names)}


def wait_served(role: str, service: str, count: int) -> dict:
    """Wait until the provider `role` got `count` requests (or goals) for `service`."""
    return {"op": "wait_served", "conn": role, "service": service, "count": count}


def advertise_action(role: str, action: str, action_type: str) -> dict:
    """Serve `action` by the Fibonacci rules (see roslibpy_driver.py)."""
    return {"op": "advertise_action", "conn": role, "action": action, "type": action_type}


def send_goal(
    role: str, name: str, action: str, action_type: str, args: Any, *, wait: bool = True
) -> dict:
    """Send a goal; its feedback and result are recorded as `name`."""
    step = {
        "op": "send_goal",
        "conn": role,
        "as": name,
        "action": action,
        "type": action_type,
        "args": args,
    }
    if not wait:
        step["wait"] = False
    return step


def wait_feedback(name: str, count: int) -> dict:
    """Wait until the goal recorded as `name` got `count` feedback messages."""
    return {"op": "wait_feedback", "as": name, "count": count}


def cancel_goal(role: str, name: str) -> dict:
    """Cancel the goal recorded as `name` with the client's own cancel method."""
    return {"op": "cancel_goal", "conn": role, "as": name}


def inproc(server: ServerProcess, *commands: dict, wait: bool = True) -> HarnessStep:
    """A harness phase: serve_fixture.py's in-process caller runs `commands` at once.

    Each command is {"op": "call"|"goal", "as": NAME, ...} (see serve_fixture.py).
    With `wait` the phase ends once all replied (as `inproc_wait`); without, at
    once, and a later `inproc_wait` phase collects the replies.
    """

    def run(running: Running) -> None:
        for command in commands:
            server.command(**command)
        if wait:
            inproc_wait(server, *(command["as"] for command in commands))(running)

    return run


def inproc_wait(server: ServerProcess, *names: str) -> HarnessStep:
    """A harness phase: wait for the in-process replies `names` (bounded).

    What each got goes into the outcome as for a driver's calls (`calls`,
    `feedback`), and the order they ended in under `order["inproc"]`.
    """

    def run(running: Running) -> None:
        for name, reply in server.replies(list(names)).items():
            running.outcome.calls[name] = {k: v for k, v in reply.items() if k in ("ok", "error")}
            if "feedback" in reply:
                running.outcome.feedback[name] = reply["feedback"]
        running.outcome.order["inproc"] = [n for n in server.reply_order if n in names]

    return run


def inproc_call(name: str, service: str, args: Any = None) -> dict:
    """An in-process call (`rwt_graph.async_calls.call_service`) for `inproc`."""
    return {"op": "call", "as": name, "service": service, "args": args}


def inproc_goal(name: str, action: str, args: Any) -> dict:
    """An in-process goal (`rwt_graph.async_calls.send_action_goal`) for `inproc`."""
    return {"op": "goal", "as": name, "action": action, "args": args}


def kill(*roles: str) -> HarnessStep:
    """A harness phase: SIGKILL the processes of `roles`."""

    def run(running: Running) -> None:
        for role in roles:
            running.kill(role)

    return run
