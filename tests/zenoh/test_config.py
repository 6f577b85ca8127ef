"""The link's options: loopback checks, the Zenoh config made of them, clear errors."""

from __future__ import annotations

import importlib.util
import json
import re
from pathlib import Path
from typing import Any

import pytest

from rwt_cli import zenoh_link
from rwt_graph.graph import Graph
from rwt_protocol.distribution import install_hint
from rwt_zenoh.config import (
    ZenohOptions,
    default_domain_id,
    endpoint_host,
    is_loopback_endpoint,
    make_config,
)
from tests.support.cli import invoke_rwt


@pytest.mark.parametrize(
    ("endpoint", "loopback"),
    [
        ("tcp/127.0.0.1:7447", True),
        ("tcp/127.3.4.5:1", True),
        ("udp/[::1]:7447", True),
        ("tcp/localhost:7447", True),
        ("tcp/0.0.0.0:7447", False),
        ("tcp/[::]:0", False),
        ("tcp/10.0.0.1:7447", False),
        ("tcp/example.org:7447", False),
        ("not an endpoint", False),
    ],
)
def test_loopback_endpoints_are_told_apart(endpoint: str, loopback: bool) -> None:
    assert is_loopback_endpoint(endpoint) is loopback


def test_an_endpoint_without_a_port_is_refused() -> None:
    with pytest.raises(ValueError, match="expected <protocol>/<host>:<port>"):
        endpoint_host("tcp/127.0.0.1")


def _json(config: Any, key: str) -> Any:
    return json.loads(config.get_json(key))


def test_a_peer_told_nothing_listens_on_loopback_with_multicast_off() -> None:
    config = make_config(ZenohOptions())
    assert _json(config, "mode") == "peer"
    assert _json(config, "listen/endpoints") == ["tcp/127.0.0.1:0"]
    assert _json(config, "scouting/multicast/enabled") is False
    assert _json(config, "timestamping/enabled") is True  # the latched cache needs it


def test_options_override_a_config_file(tmp_path: Path) -> None:
    path = tmp_path / "zenoh.json5"
    path.write_text('{ mode: "client", scouting: { multicast: { enabled: true } } }')
    options = ZenohOptions(mode="peer", config_file=path, connect=("tcp/127.0.0.1:1",))
    config = make_config(options)
    assert _json(config, "mode") == "peer"
    assert _json(config, "scouting/multicast/enabled") is False
    assert _json(config, "connect/endpoints") == ["tcp/127.0.0.1:1"]


def test_a_bad_config_file_or_mode_is_one_clear_error(tmp_path: Path) -> None:
    path = tmp_path / "bad.json5"
    path.write_text("{ mode: ")
    with pytest.raises(ValueError, match="cannot read zenoh config"):
        make_config(ZenohOptions(config_file=path))
    with pytest.raises(ValueError, match="zenoh mode 'hub'"):
        make_config(ZenohOptions(mode="hub"))


def test_the_domain_comes_from_ros_domain_id(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("ROS_DOMAIN_ID", "42")
    assert default_domain_id() == 42
    monkeypatch.setenv("ROS_DOMAIN_ID", "not a number")
    assert default_domain_id() == 0


def test_without_the_extra_zenoh_options_say_how_to_install_it(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    real = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util, "find_spec", lambda name: None if name == "zenoh" else real(name)
    )
    with pytest.raises(
        ValueError, match=re.escape(f"--zenoh needs Eclipse Zenoh: {install_hint('zenoh')}")
    ):
        zenoh_link.zenoh_options(
            mode="peer", connect=None, listen=None, config_file=None, domain_id=None
        )


def test_workers_refuse_transports_they_cannot_share() -> None:
    result = invoke_rwt("serve", "--workers", "2", "--stdio")
    assert result.exit_code == 2
    assert "--workers shares TCP ports" in result.stderr


def test_a_missing_zenoh_config_file_is_a_usage_error(tmp_path: Path) -> None:
    missing = tmp_path / "nope.json5"
    result = invoke_rwt("serve", "--zenoh", "--zenoh-config", str(missing))
    assert result.exit_code == 2
    assert f"no such file: {missing}" in result.stderr


def test_graph_taps_see_each_publish_and_a_broken_tap_hurts_nobody() -> None:
    graph = Graph()
    seen: list[tuple[str, object, bool]] = []

    def broken(*_: object) -> None:
        raise RuntimeError("a bug in a tap")

    graph.taps += [
        broken,
        lambda topic, event, client, latch: seen.append((topic.name, event.msg, latch)),
    ]
    got: list[object] = []
    subscription = graph.create_subscription("/t", got.append, "std_msgs/msg/String")
    publisher = graph.create_publisher("/t", "std_msgs/msg/String", latch=True)
    publisher.publish({"data": "x"})
    assert got == [{"data": "x"}]
    assert seen == [("/t", {"data": "x"}, True)]
    subscription.close()
    publisher.close()
    assert "/t" not in graph.topics  # a tap keeps no topic alive


def test_zenoh_refuses_the_ros1_dialect() -> None:
    result = invoke_rwt("serve", "--zenoh", "--dialect", "ros1")
    assert result.exit_code == 2
    assert "not --dialect ros1" in result.stderr
