"""``import rwt`` is closed: every type its API takes, returns or raises is in ``rwt``."""

from __future__ import annotations

import ast
import builtins
import inspect
import re
import subprocess
import sys
import textwrap
from collections.abc import Callable, Iterator

import pytest

import rwt
from tests.docs.api_reference import namespace_of, ours

# Members that are plumbing between rwt's own packages, not API: the hooks the
# transports, the session and the Zenoh link's helpers call. (The port a session
# drives is not even a member: it is ``Graph.port``, an attribute.)
PLUMBING = {
    "AccessPolicy.check",
    "ConsoleSite.answer",
    "LocalSubscription.on_message",
    "RosbridgeServer.open_session",
    "TFRepublisher.run_goal",
    "TFRepublisher.subscription",
    "ZenohLink.declare_publisher",
    "ZenohLink.declare_queryable",
    "ZenohLink.declare_service",
    "ZenohLink.entity_of",
}
# Classes rwt hands out (from create_*, open_*, send_goal...) and never asks a user
# to build: their constructors are internal.
HANDED_OUT = {
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
            # a docstring may name an error its module does not import: rwt must have it
            yield getattr(rwt, name, f"unknown name {name}")
        else:
            if not isinstance(value, str):  # a string is a type alias of a third party's types
                yield value


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


def unreachable_types() -> dict[str, set[str]]:
    """Types the API uses that ``rwt`` does not export, and where each is used."""
    missing: dict[str, set[str]] = {}
    todo = [getattr(rwt, name) for name in rwt.__all__ if name != "__version__"]
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
                elif (
                    inspect.isclass(kind)
                    and ours(kind.__module__)
                    and not kind.__name__.startswith("_")
                ):
                    todo.append(kind)
                    if getattr(rwt, kind.__name__, None) is not kind:
                        missing.setdefault(f"{kind.__module__}.{kind.__name__}", set()).add(where)
    return missing


def test_every_type_the_api_takes_returns_or_raises_is_in_rwt() -> None:
    assert unreachable_types() == {}


def test_every_public_name_says_it_is_rwts() -> None:
    assert sorted(dir(rwt)) == sorted(rwt.__all__)
    for name in rwt.__all__:
        value = getattr(rwt, name)
        if name != "__version__":
            assert value.__module__ == "rwt", name


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
    assert 'pip install "rwt[server]"' in run.stderr
    assert "Traceback" not in run.stderr
