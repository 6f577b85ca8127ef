"""The public API is small and closed: ``rwt`` and its namespaces hold every type it uses.

``rwt`` keeps what most programs need (at most 40 names); the rest is in
namespaces that follow the docs pages (``rwt.tf``, ``rwt.bag``...). Each
namespace is closed over its own types: every type its functions and methods
take, return or raise is in it, in ``rwt``, or in a namespace it builds on
(``BUILDS_ON``), never only in an implementation package.
"""

from __future__ import annotations

import ast
import builtins
import importlib
import inspect
import re
import subprocess
import sys
import textwrap
from collections.abc import Callable, Iterator
from pathlib import Path
from types import ModuleType

import pytest

import rwt
from rwt._names import NAMESPACES, PUBLIC
from tests.docs.api_reference import namespace_of, ours

# Members that are plumbing between rwt's own packages, not API: the hooks the
# transports, the session and the Zenoh link's helpers call. (The port a session
# drives is not even a member: it is ``Graph.port``, an attribute.)
PLUMBING = {
    "AccessPolicy.check",
    "ConsoleSite.answer",
    "Envelope.admit",  # the graph's publish hook, the server's timer and audit (rwt_graph.safety)
    "Envelope.connected",
    "Envelope.expire",
    "Envelope.gone",
    "Envelope.install",
    "Envelope.next_deadline",
    "Envelope.publish_status",
    "Envelope.record_approval",
    "LocalSubscription.on_message",
    "GraphServer.add_frontend",
    "GraphServer.features",
    "GraphServer.open_session",
    "GraphServer.rules",  # with settings: what front ends read (rwt_transports.host.FrontEndHost)
    "GraphServer.settings",
    "TFRepublisher.run_goal",
    "TFRepublisher.subscription",
    "ZenohLink.declare_publisher",
    "ZenohLink.declare_queryable",
    "ZenohLink.declare_service",
    "ZenohLink.entity_of",
    "ZenohLink.put_queued",
}
# Classes rwt hands out (from create_*, open_*, send_goal...) and never asks a user
# to build: their constructors are internal.
HANDED_OUT = {
    "Envelope",
    "GoalContext",
    "GoalHandle",
    "LocalActionServer",
    "LocalPublisher",
    "LocalService",
    "LocalSubscription",
    "MemoryConnection",
    "Ros2Link",
    "ServerGoal",
    "TFBuffer",
    "TFRepublisher",
    "ZenohLink",
}


# The namespaces a namespace's API may name types of, besides its own, ``rwt``'s
# and ``rwt.errors``' (every feature raises protocol or parameter errors).
BUILDS_ON = {
    "rwt.client": {"rwt.types"},  # message_class(registry)
    "rwt.tf": {"rwt.types"},  # StampedTransform.message(dialect)
    "rwt.video": {"rwt.server"},  # VideoConfig.console: the console's site
}


def spaces() -> dict[str, ModuleType]:
    """``rwt`` and its namespaces, by name."""
    return {space: importlib.import_module(space) for space in PUBLIC}


def public_place() -> dict[int, str]:
    """``id`` of every public value -> its place, ``rwt.tf.TFBuffer``."""
    return {
        id(getattr(module, name)): f"{space}.{name}"
        for space, module in spaces().items()
        for name in module.__all__
        if name != "__version__"
    }


def _types_of(function: Callable[..., object]) -> Iterator[object]:
    """The classes ``function``'s annotations name and its docstring's ``Raises:`` lists."""
    namespace = namespace_of(function.__globals__["__name__"])
    names: list[str] = []
    for parameter, annotation in function.__annotations__.items():
        if parameter == "self":
            continue
        if isinstance(annotation, str):
            tree = ast.parse(annotation, mode="eval")
            names += [
                ast.unparse(node)
                for node in ast.walk(tree)
                if isinstance(node, ast.Name | ast.Attribute)
            ]
        elif inspect.isclass(annotation):
            yield annotation
    raises = re.search(r"Raises:\n(.*?)(?:\n\n|\Z)", inspect.getdoc(function) or "", re.S)
    if raises:
        names += re.findall(r"^ {4}([A-Za-z_.]+):", raises.group(1), re.M)
    for name in names:
        try:
            value = eval(name, namespace, vars(builtins))
        except (NameError, AttributeError):
            # a docstring may name an error its module does not import: the API must have it
            yield _by_name(name)
        else:
            if not isinstance(value, str):  # a string is a type alias of a third party's types
                yield value


def _by_name(name: str) -> object:
    for module in spaces().values():
        if name in module.__all__:
            return getattr(module, name)
    return f"unknown name {name}"


def _functions(value: object) -> Iterator[tuple[str, Callable[..., object]]]:
    if not inspect.isclass(value):
        function = inspect.unwrap(value)  # type: ignore[arg-type]
        yield function.__name__, function
        return
    for name in dir(value):
        if name.startswith("_") and name != "__init__":
            continue
        member = inspect.getattr_static(value, name)
        member = member.fget if isinstance(member, property) else member
        member = inspect.unwrap(getattr(member, "__func__", member))
        where = f"{value.__name__}.{name}"
        if (
            inspect.isfunction(member)
            and ours(member.__globals__.get("__name__", ""))
            and where not in PLUMBING
            and not (name == "__init__" and value.__name__ in HANDED_OUT)
        ):
            yield where, member


def unreachable_types(space: str) -> dict[str, set[str]]:
    """Types the API of ``space`` uses that it may not name, and where each is used.

    Each is either in no public place (``rwt_graph.x.Thing``) or in a namespace
    ``space`` does not build on (``rwt.bag.BagError (not for rwt.tf)``).
    """
    module = importlib.import_module(space)
    places = public_place()
    allowed = {space, "rwt", "rwt.errors", *BUILDS_ON.get(space, ())}
    if space == "rwt":
        allowed = set(PUBLIC)  # the core may name a type of any namespace
    missing: dict[str, set[str]] = {}
    todo = [getattr(module, name) for name in module.__all__ if name != "__version__"]
    done: list[object] = []
    while todo:
        value = todo.pop()
        if any(value is seen for seen in done):
            continue
        done.append(value)
        for where, function in _functions(value):
            for kind in _types_of(function):
                if isinstance(kind, str):
                    missing.setdefault(kind, set()).add(where)
                    continue
                if not (
                    inspect.isclass(kind)
                    and ours(kind.__module__)
                    and not kind.__name__.startswith("_")
                ):
                    continue
                place = places.get(id(kind))
                if place is None:
                    todo.append(kind)  # walked here, so every unplaced type is found
                    missing.setdefault(f"{kind.__module__}.{kind.__name__}", set()).add(where)
                elif place.rpartition(".")[0] not in allowed:
                    missing.setdefault(f"{place} (not for {space})", set()).add(where)
    return missing


@pytest.mark.parametrize("space", PUBLIC)
def test_every_type_the_api_takes_returns_or_raises_is_in_its_namespace(space: str) -> None:
    assert unreachable_types(space) == {}


def type_checking_imports(module: ModuleType) -> set[tuple[str, str]]:
    """The (home, name) pairs a namespace module imports for type checkers only."""
    assert module.__file__ is not None
    tree = ast.parse(Path(module.__file__).read_text(encoding="utf-8"))
    blocks = [
        node
        for node in tree.body
        if isinstance(node, ast.If) and ast.unparse(node.test) == "TYPE_CHECKING"
    ]
    return {
        (stmt.module or "", alias.name)
        for block in blocks
        for stmt in block.body
        if isinstance(stmt, ast.ImportFrom) and not stmt.level  # not ``from . import tf``
        for alias in stmt.names
    }


@pytest.mark.parametrize("space", PUBLIC)
def test_type_checkers_see_each_name_from_its_home_in_the_table(space: str) -> None:
    # the table serves the names at run time, these imports serve them to type checkers
    listed = {(home, name) for home, names in PUBLIC[space].items() for name in names}
    assert type_checking_imports(importlib.import_module(space)) == listed


@pytest.mark.parametrize("space", PUBLIC)
def test_every_public_name_says_where_it_is(space: str) -> None:
    module = importlib.import_module(space)
    listed = sorted(name for names in PUBLIC[space].values() for name in names)
    assert sorted(set(module.__all__) - {"__version__"}) == listed
    assert sorted(dir(module)) == sorted([*module.__all__, *(NAMESPACES if space == "rwt" else ())])
    for name in module.__all__:
        value = getattr(module, name)
        if name != "__version__":
            assert value.__module__ == space, name


def test_rwt_is_small_and_each_name_has_one_place() -> None:
    assert len(rwt.__all__) <= 40
    everywhere = [name for module in spaces().values() for name in module.__all__]
    assert len(everywhere) == len(set(everywhere))
    for name in NAMESPACES:
        assert getattr(rwt, name) is sys.modules[f"rwt.{name}"]


# public since the split, in a namespace from the start: never an ``rwt.X``
NEVER_IN_RWT = {
    "Compat",
    "Connection",
    "McpOptions",
    "McpSiblings",
    "Placement",
    "HttpApiOptions",
    "Admitted",
    "FoxgloveLimits",
    "FoxgloveOptions",
    "PlaybackStatus",
    "UnknownNameError",
    "TopicUse",
    "WebRtcOptions",
    "auth_query",
    "rosauth_op",
    "shortcut_report",
    "Durability",  # protocol 2.1.0's QoS policies: in rwt.types from the first
    "History",
    "Reliability",
    # rwt.safety (docs/safety.md)
    "AuditTrail",
    "CallRule",
    "Envelope",
    "EnvelopeError",
    "RulesError",
    "SafetyEvent",
    "SafetyRules",
    "TopicRule",
    "load_rules",
    "parse_rules",
}


def test_docs_say_where_every_name_that_left_rwt_went() -> None:
    text = (Path(__file__).parents[2] / "docs" / "api.md").read_text("utf-8")
    rows = dict(re.findall(r"^\| `rwt\.(\w+)` \| `(rwt\.[\w.]+)` \|", text, re.M))
    places = {
        name: f"{space}.{name}"
        for space, homes in PUBLIC.items()
        if space != "rwt"
        for names in homes.values()
        for name in names
        if name not in NEVER_IN_RWT
    }
    assert rows == places


def test_a_namespace_loads_its_homes_with_its_names_only() -> None:
    """``import rwt.bag`` loads no bag code; ``rwt.bag.Recorder`` does (lazy_imports)."""
    script = textwrap.dedent(
        """
        import sys
        import rwt.bag, rwt.media, rwt.zenoh, rwt.ros2, rwt.video

        print(sorted(m for m in sys.modules if m.split(".")[0] in
              {"rwt_bag", "rosbags", "numpy", "PIL", "zenoh", "rclpy", "rwt_video"}))
        rwt.bag.Recorder
        print("rwt_bag" in sys.modules, rwt.bag.Recorder.__module__)
        """
    )
    run = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=60, check=False
    )
    assert run.returncode == 0, run.stderr
    assert run.stdout.splitlines() == ["[]", "True rwt.bag"]


def test_the_names_are_the_homes_own() -> None:
    from rwt_graph.graph import Graph  # noqa: PLC0415
    from rwt_protocol.errors import CallTimeoutError, RwtError, ServiceCallError  # noqa: PLC0415
    from rwt_protocol.server.session import SessionConfig  # noqa: PLC0415

    assert (rwt.Graph, rwt.RwtError, rwt.SessionConfig) == (Graph, RwtError, SessionConfig)
    assert (
        issubclass(rwt.ServiceCallError, rwt.RwtError) and rwt.ServiceCallError is ServiceCallError
    )
    assert issubclass(CallTimeoutError, ServiceCallError) and issubclass(
        CallTimeoutError, TimeoutError
    )


def test_a_traceback_names_rwt_even_for_a_name_never_looked_up() -> None:
    script = textwrap.dedent(
        """
        import rwt

        graph = rwt.Graph()
        graph.create_publisher("/chatter", "std_msgs/msg/String").publish({"data": 5})
        """
    )
    run = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=60, check=False
    )
    assert run.stderr.splitlines()[-1] == "rwt.FieldError: expected string, got int at $.data"


def test_an_unknown_name_is_an_attribute_error() -> None:
    with pytest.raises(AttributeError, match="Nothing"):
        rwt.Nothing  # type: ignore[attr-defined]  # noqa: B018


def test_the_client_works_without_the_server_extra() -> None:
    """With numpy, Pillow, typer, rich, h11 and rosbags unavailable, the client still imports."""
    script = textwrap.dedent(
        """
        import sys

        class Missing:
            def find_spec(self, name, path=None, target=None):
                if name.split(".")[0] in {"numpy", "PIL", "typer", "rich", "h11", "rosbags"}:
                    raise ModuleNotFoundError(f"No module named {name!r}", name=name)
                return None

        sys.meta_path.insert(0, Missing())
        import rwt
        from rwt_protocol.client import ClientSession

        assert rwt.Ros and rwt.SyncRos and rwt.Topic and rwt.ServiceCallError
        assert rwt.StatusLevel and rwt.ConnectionClosedError and rwt.GoalHandle
        session = ClientSession()
        session.subscribe("/chatter", "std_msgs/String")
        events = session.receive_frame('{"op":"publish","topic":"/chatter","msg":{"data":"hi"}}')
        print(session.frames_to_send(), events)
        try:
            rwt.Graph
        except ModuleNotFoundError as error:
            print("server extra missing:", error.name)
        """
    )
    run = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=60, check=False
    )
    assert run.returncode == 0, run.stderr
    assert "topic='/chatter'" in run.stdout and "msg={'data': 'hi'}" in run.stdout
    assert "server extra missing:" in run.stdout


def test_the_command_says_which_extra_it_needs() -> None:
    script = textwrap.dedent(
        """
        import sys

        class Missing:
            def find_spec(self, name, path=None, target=None):
                if name.split(".")[0] == "typer":
                    raise ModuleNotFoundError(f"No module named {name!r}", name=name)
                return None

        sys.meta_path.insert(0, Missing())
        sys.argv = ["rwt", "serve"]
        from rwt._cli import main
        main()
        """
    )
    run = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=60, check=False
    )
    assert run.returncode == 2
    assert 'pip install "rwt-rosbridge[server]"' in run.stderr
    assert "Traceback" not in run.stderr
