"""The ROS 2 differential (conformance/ros2_differential.py) against rosbridge_suite 2.1.0.

Runs only when ``RWT_ROSBRIDGE_ROS2_URL`` names the peer's WebSocket and
``RWT_ROSBRIDGE_ROS2_DOMAIN`` its ``ROS_DOMAIN_ID`` (the peer's rosapi must be fresh:
its set_param stalls it, docs/ros2.md "Compared with rosbridge_suite 2.1.0"). It asserts
where both bridges agree and where rwt is right per the spec and the peer differs.
"""

from __future__ import annotations

import os
from typing import TYPE_CHECKING

import pytest

from conformance import ros2_differential as diff

from .support import skip_without_rclpy

if TYPE_CHECKING:
    from collections.abc import Iterator

URL = os.environ.get(diff.PEER_ENV)
DOMAIN = os.environ.get("RWT_ROSBRIDGE_ROS2_DOMAIN")

pytestmark = [
    skip_without_rclpy(),
    pytest.mark.skipif(
        not (URL and DOMAIN),
        reason=f"no rosbridge_suite 2.1.0 peer: set {diff.PEER_ENV} and RWT_ROSBRIDGE_ROS2_DOMAIN",
    ),
]


@pytest.fixture(scope="module")
def results() -> Iterator[dict[str, dict[str, str]]]:
    """Every scenario on both bridges, once for the module."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("ROS_DOMAIN_ID", str(DOMAIN))
        with diff.rwt_server() as rwt_url:
            assert URL is not None
            yield diff.run_all(URL, rwt_url)


@pytest.mark.parametrize(
    "scenario",
    ["topic ws -> ROS", "service ROS calls ws"],
)
def test_both_bridges_agree(results: dict[str, dict[str, str]], scenario: str) -> None:
    row = results[scenario]
    assert row["peer"] == row["rwt"], row


def test_both_bridges_carry_ros_topics_and_actions(results: dict[str, dict[str, str]]) -> None:
    assert results["topic ROS -> ws"]["rwt"].startswith("first: {'data': ")
    # the peer misses this at times (docs/ros2.md, row 3); rwt must not (D13)
    late = results["transient-local, late subscriber"]["rwt"]
    assert late == "late subscriber got {'data': 'latched'}"
    action = results["action goal, feedback, result, cancel"]["rwt"]
    assert "'status': 4, 'result': True, 'values': {'sequence': [0, 1, 1, 2]}" in action
    # cancel_action_goal right after send_action_goal: the goal ends CANCELED (5)
    assert "cancelled [{'status': 5, 'result': True}]" in action


def test_rwt_answers_bad_input_with_error_statuses(results: dict[str, dict[str, str]]) -> None:
    assert "error: subscribe: unknown message type" in results["type not installed"]["rwt"]
    assert "expected string, got int" in results["wrong field type (publish)"]["rwt"]
    assert "expected int8 in [-128, 127], got 300" in results["int out of range (publish)"]["rwt"]
    assert "expected bool, got str" in results["service call with wrong arg type"]["rwt"]


def test_rwt_reaches_a_ros2_nodes_parameters(results: dict[str, dict[str, str]]) -> None:
    row = results["parameters get/set/names"]["rwt"]
    assert 'get again {"reason": "", "successful": true, "value": "2.5"}' in row
    assert "/params_rwt:speed" in row
