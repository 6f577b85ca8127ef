"""``import rwt`` gives what embedding code and client users need, and nothing else."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import rwt

PUBLIC = [
    "Action",
    "CallTimeoutError",
    "GoalOutcome",
    "Graph",
    "Player",
    "Recorder",
    "Ros",
    "RosbridgeServer",
    "RwtError",
    "ServerConfig",
    "Service",
    "ServiceCallError",
    "SyncRos",
    "Topic",
    "__version__",
    "call_service",
    "send_action_goal",
]


def test_the_public_names_are_pinned() -> None:
    assert sorted(rwt.__all__) == sorted(PUBLIC)
    assert sorted(dir(rwt)) == sorted(PUBLIC)


def test_every_public_name_resolves_to_its_home() -> None:
    from rwt_client import Ros  # noqa: PLC0415
    from rwt_graph.graph import Graph  # noqa: PLC0415
    from rwt_protocol.errors import CallTimeoutError, RwtError, ServiceCallError  # noqa: PLC0415
    from rwt_transports.server import RosbridgeServer, ServerConfig  # noqa: PLC0415

    assert (rwt.Graph, rwt.Ros, rwt.RosbridgeServer, rwt.ServerConfig) == (
        Graph,
        Ros,
        RosbridgeServer,
        ServerConfig,
    )
    assert (
        issubclass(rwt.ServiceCallError, rwt.RwtError) and rwt.ServiceCallError is ServiceCallError
    )
    assert issubclass(CallTimeoutError, ServiceCallError) and issubclass(
        CallTimeoutError, TimeoutError
    )
    assert RwtError is rwt.RwtError
    for name in PUBLIC:
        assert getattr(rwt, name) is not None


def test_an_unknown_name_is_an_attribute_error() -> None:
    try:
        rwt.Nothing  # type: ignore[attr-defined]  # noqa: B018
    except AttributeError as error:
        assert "Nothing" in str(error)
    else:
        raise AssertionError("rwt.Nothing should not exist")


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
