"""Services with real clients: roslibpy, roslib (Node) and in-process code, each way.

Providers: roslibpy (`Service.advertise`), roslib (`Service.advertise`, and
`advertiseAsync` where the answer comes later) and Python code in the server
process (`Graph.create_service`, in serve_fixture.py). Callers: roslibpy
(`Service.call` with callbacks), roslib (`Service.callService`) and in-process
code (`rwt_graph.async_calls.call_service`, driven through serve_fixture.py's
stdin). Every provider follows the same reply rules (roslibpy_driver.py), so
one table of expectations fits all nine pairs. The service types are SetBool,
Trigger, Empty, AddTwoInts and `rwt_test_interfaces/srv/Scale`, a custom
service loaded with `--interfaces tests/integration/data`.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from .client_harness import (
    HARNESS,
    Outcome,
    Phase,
    ServerProcess,
    advertise_service,
    call,
    connect,
    inproc,
    inproc_call,
    inproc_wait,
    kill,
    run_scenario,
    sync,
    wait_calls,
    wait_served,
)

PY, JS, INPROC = "roslibpy", "roslibjs", "inproc"
PREFIX = {PY: "/py/", JS: "/js/", INPROC: "/inproc/"}

SET_BOOL = "std_srvs/SetBool"
TRIGGER = "std_srvs/srv/Trigger"
EMPTY = "std_srvs/Empty"
ADD = "example_interfaces/srv/AddTwoInts"
SCALE = "rwt_test_interfaces/srv/Scale"

#: (service under the provider's prefix, type, reply rule of the drivers)
SERVICES = [
    ("set_bool", SET_BOOL, "set_bool"),
    ("trigger", TRIGGER, "trigger"),
    ("empty", EMPTY, "empty"),
    ("add", ADD, "add"),
    ("scale", SCALE, "scale"),
    ("refuse", TRIGGER, "refuse"),
]
TYPES = {service: srv_type for service, srv_type, _ in SERVICES}

POINTS = [{"x": 1.5, "y": -2.0}, {"x": 0.0, "y": 4.0}]
#: (call, service, request, response): missing request fields take their defaults.
CALLS = [
    ("on", "set_bool", {"data": True}, {"success": True, "message": "on"}),
    ("off", "set_bool", {}, {"success": False, "message": "off"}),
    ("trigger", "trigger", {}, {"success": True, "message": "triggered"}),
    ("empty", "empty", None, {}),
    ("add", "add", {"a": 40, "b": 2}, {"sum": 42}),
    ("add_default", "add", {"a": -7}, {"sum": -7}),
    (
        "scale",
        "scale",
        {"points": POINTS, "factor": 2.0},
        {"points": [{"x": 3.0, "y": -4.0}, {"x": 0.0, "y": 8.0}], "note": "2 points"},
    ),
    ("scale_default", "scale", {"points": [{"x": 5}]}, {"points": [{"x": 5.0, "y": 0.0}], "note": "1 points"}),  # noqa: E501
]  # fmt: skip
#: What the provider got for each service, per caller: defaults filled in.
REQUESTS_SEEN = {
    "set_bool": [{"data": True}, {"data": False}],
    "trigger": [{}],
    "empty": [{}],
    "add": [{"a": 40, "b": 2}, {"a": -7, "b": 0}],
    "scale": [
        {"points": POINTS, "factor": 2.0},
        {"points": [{"x": 5.0, "y": 0.0}], "factor": 1.0},  # factor's written default
    ],
    "refuse": [{}],
}
#: The reason each provider's refusal reaches every caller with.
REFUSED = {
    PY: "service call failed",  # roslibpy's callback can only return False
    JS: "Error: refused",  # advertiseAsync sends the thrown error's text
    INPROC: "service /inproc/refuse failed: refused",
}
CALLERS = {"py_caller": PY, "js_caller": JS}


def provider_phase(role: str, client: str) -> Phase:
    prefix = PREFIX[client]
    steps = [connect(role)]
    steps += [advertise_service(role, prefix + s, t, rule) for s, t, rule in SERVICES]
    return (role, [*steps, sync(role)])


def caller_phase(role: str, provider: str) -> Phase:
    """All calls at once (each is answered on its own), then wait for every answer."""
    prefix = PREFIX[provider]
    steps = [connect(role)]
    names = []
    for name, service, args, _ in CALLS:
        steps.append(
            call(role, f"{role}:{name}", prefix + service, TYPES[service], args, wait=False)
        )
        names.append(f"{role}:{name}")
    for extra in ("refuse", "missing"):
        steps.append(call(role, f"{role}:{extra}", prefix + extra, TRIGGER, {}, wait=False))
        names.append(f"{role}:{extra}")
    return (role, [*steps, wait_calls(*names)])


def inproc_caller_phase(server: ServerProcess, provider: str) -> Phase:
    prefix = PREFIX[provider]
    commands = [inproc_call(f"inproc:{n}", prefix + s, args) for n, s, args, _ in CALLS]
    commands += [inproc_call(f"inproc:{n}", prefix + n, {}) for n in ("refuse", "missing")]
    return (HARNESS, inproc(server, *commands))


def assert_answers(outcome: Outcome, caller: str, provider: str) -> None:
    prefix = PREFIX[provider]
    for name, _, _, response in CALLS:
        assert outcome.ok(f"{caller}:{name}") == response, (caller, name)
    assert outcome.error(f"{caller}:refuse") == REFUSED[provider]
    assert outcome.error(f"{caller}:missing") == f"service {prefix}missing does not exist"


@pytest.mark.node
@pytest.mark.parametrize("provider", [PY, JS, INPROC])
def test_every_caller_gets_every_provider_s_answers(
    fixture_server: ServerProcess, tmp_path: Path, provider: str
) -> None:
    """roslibpy, roslib and in-process callers against one provider kind, all five types."""
    phases: list[Phase] = []
    if provider != INPROC:
        phases.append(provider_phase("provider", provider))
    phases += [caller_phase(role, provider) for role in CALLERS]
    phases.append(inproc_caller_phase(fixture_server, provider))
    if provider != INPROC:
        phases.append(("provider", []))  # stays connected until every caller is done
    clients = {"provider": provider, **CALLERS}

    outcome = run_scenario(fixture_server.url, phases, clients, tmp_path)

    for caller in (*CALLERS, "inproc"):
        assert_answers(outcome, caller, provider)
    if provider != INPROC:
        # The requests as the provider's callback got them, callers in turn:
        # roslibpy, roslib, in-process.
        served = outcome.served["provider"]
        prefix = PREFIX[provider]
        assert {name: served[prefix + name] for name in REQUESTS_SEEN} == {
            name: requests * 3 for name, requests in REQUESTS_SEEN.items()
        }


GATHER = 12  # serve_fixture.GATHER: the in-process /inproc/gather holds this many


def batch(role: str, service: str) -> tuple[list[dict], list[str]]:
    """GATHER concurrent AddTwoInts calls, each with its own operands."""
    names = [f"{role}:{i}" for i in range(GATHER)]
    steps = [
        call(role, n, service, ADD, {"a": i, "b": 1000 * i}, wait=False)
        for i, n in enumerate(names)
    ]
    return [*steps, wait_calls(*names)], names


@pytest.mark.node
def test_twelve_concurrent_calls_answered_newest_first(
    fixture_server: ServerProcess, tmp_path: Path
) -> None:
    """Providers answer only once 12 calls wait, newest first; each caller gets its own sum.

    roslibpy and in-process code call a roslib provider (`advertiseAsync`); roslib
    calls an in-process provider (an async handler).
    """
    py_steps, py_names = batch("py_caller", "/js/gather")
    js_steps, js_names = batch("js_caller", "/inproc/gather")
    inproc_names = [f"inproc:{i}" for i in range(GATHER)]
    commands = [
        inproc_call(name, "/js/gather", {"a": i, "b": 1000 * i})
        for i, name in enumerate(inproc_names)
    ]
    phases: list[Phase] = [
        (
            "js",
            [
                connect("provider"),
                advertise_service("provider", "/js/gather", ADD, "gather", count=GATHER),
                sync("provider"),
            ],
        ),
        ("py", [connect("py_caller"), *py_steps]),
        (HARNESS, inproc(fixture_server, *commands)),
        ("js", [connect("js_caller"), *js_steps]),
    ]

    outcome = run_scenario(fixture_server.url, phases, {"js": JS, "py": PY}, tmp_path)

    for names in (py_names, inproc_names, js_names):
        assert [outcome.ok(name) for name in names] == [{"sum": 1001 * i} for i in range(GATHER)]
    assert outcome.order["py_caller"] == py_names[::-1]
    assert outcome.order["inproc"] == inproc_names[::-1]
    assert outcome.order["js_caller"] == js_names[::-1]
    assert (
        outcome.served["provider"]["/js/gather"]
        == [{"a": i, "b": 1000 * i} for i in range(GATHER)] * 2
    )


@pytest.mark.node
def test_provider_killed_mid_call_fails_the_waiting_callers(
    fixture_server: ServerProcess, tmp_path: Path
) -> None:
    """SIGKILL a roslibpy and a roslib provider while calls wait on them: every caller
    (roslib, roslibpy, in-process) hears back with the reason, long before the 30 s
    call timeout."""
    args = {"points": POINTS, "factor": 3.0}

    def provide(role: str, service: str, srv_type: str) -> Phase:
        return (
            role,
            [connect(role), advertise_service(role, service, srv_type, "hold"), sync(role)],
        )

    def ask(role: str, service: str) -> Phase:
        return (role, [connect(role), call(role, role, service, SCALE, args, wait=False)])

    phases: list[Phase] = [
        provide("py_provider", "/py/hold", SCALE),
        provide("js_provider", "/js/hold", "rwt_test_interfaces/Scale"),
        ask("js_caller", "/py/hold"),
        ask("py_caller", "/js/hold"),
        (HARNESS, inproc(fixture_server, inproc_call("inproc", "/js/hold", args), wait=False)),
        # roslibpy's provider blocks in its first callback: it reads no second request
        ("py_provider", [wait_served("py_provider", "/py/hold", 1)]),
        ("js_provider", [wait_served("js_provider", "/js/hold", 2)]),
        (HARNESS, kill("py_provider", "js_provider")),
        ("py_caller", [wait_calls("py_caller")]),
        ("js_caller", [wait_calls("js_caller")]),
        (HARNESS, inproc_wait(fixture_server, "inproc")),
    ]
    clients = {"py_provider": PY, "js_provider": JS, "py_caller": PY, "js_caller": JS}

    outcome = run_scenario(fixture_server.url, phases, clients, tmp_path)

    # roslibpy's errback, roslib's failure callback and ServiceCallError get the reason
    assert outcome.error("js_caller") == "service /py/hold is gone: its provider disconnected"
    assert outcome.error("py_caller") == "service /js/hold is gone: its provider disconnected"
    assert outcome.error("inproc") == "service /js/hold is gone: its provider disconnected"
