"""rosapi TypeDefs: message, service and action details, ROS 2 shapes (REF §7.1)."""

from __future__ import annotations

from pathlib import Path

import pytest

from rwt_graph.graph import Graph
from rwt_graph.rosapi import install_rosapi
from rwt_graph.types import TypeRegistry
from tests.conftest import FakeClock, Peer
from tests.session.rosapi_support import call, call_raw, connect


@pytest.fixture
def client(graph: Graph) -> Peer:
    install_rosapi(graph)
    return connect(graph, "c")


def typedef(type_name: str, **fields: list[object]) -> dict[str, object]:
    """A TypeDef; ``fields`` maps each field name to [type, arraylen, example]."""
    return {
        "type": type_name,
        "fieldnames": list(fields),
        "fieldtypes": [spec[0] for spec in fields.values()],
        "fieldarraylen": [spec[1] for spec in fields.values()],
        "examples": [spec[2] for spec in fields.values()],
        "constnames": [],
        "constvalues": [],
    }


HEADER = typedef(
    "std_msgs/Header", stamp=["builtin_interfaces/Time", -1, "{}"], frame_id=["string", -1, ""]
)
TIME = typedef("builtin_interfaces/Time", sec=["int32", -1, "0"], nanosec=["uint32", -1, "0"])


def test_message_details_lists_the_type_then_each_nested_type_once(client: Peer) -> None:
    status = typedef(
        "sensor_msgs/NavSatStatus", status=["int8", -1, "0"], service=["uint16", -1, "0"]
    )
    status["constnames"] = [
        "STATUS_UNKNOWN", "STATUS_NO_FIX", "STATUS_FIX", "STATUS_SBAS_FIX", "STATUS_GBAS_FIX",
        "SERVICE_UNKNOWN", "SERVICE_GPS", "SERVICE_GLONASS", "SERVICE_COMPASS", "SERVICE_GALILEO",
    ]  # fmt: skip
    status["constvalues"] = ["-2", "-1", "0", "1", "2", "0", "1", "2", "4", "8"]
    fix = typedef(
        "sensor_msgs/NavSatFix",
        header=["std_msgs/Header", -1, "{}"],
        status=["sensor_msgs/NavSatStatus", -1, "{}"],
        latitude=["double", -1, "0.0"],
        longitude=["double", -1, "0.0"],
        altitude=["double", -1, "0.0"],
        position_covariance=["double", 9, "[]"],
        position_covariance_type=["uint8", -1, "0"],
    )
    fix["constnames"] = [
        "COVARIANCE_TYPE_UNKNOWN",
        "COVARIANCE_TYPE_APPROXIMATED",
        "COVARIANCE_TYPE_DIAGONAL_KNOWN",
        "COVARIANCE_TYPE_KNOWN",
    ]
    fix["constvalues"] = ["0", "1", "2", "3"]
    for spelling in ("sensor_msgs/NavSatFix", "sensor_msgs/msg/NavSatFix"):
        assert call(client, "/rosapi/message_details", type=spelling) == {
            "typedefs": [fix, HEADER, TIME, status]
        }


def test_arrays_of_messages_and_written_defaults(client: Peer) -> None:
    [polygon, point] = call(client, "/rosapi/message_details", type="geometry_msgs/Polygon")[
        "typedefs"
    ]
    assert polygon == typedef("geometry_msgs/Polygon", points=["geometry_msgs/Point32", 0, "[]"])
    assert point["fieldtypes"] == ["float", "float", "float"]
    [quaternion] = call(client, "rosapi/message_details", type="geometry_msgs/Quaternion")[
        "typedefs"
    ]
    assert quaternion["examples"] == ["0.0", "0.0", "0.0", "1.0"]


def test_ros2_idl_names_for_every_primitive(tmp_path: Path, clock: FakeClock) -> None:
    folder = tmp_path / "demo_msgs" / "msg"
    folder.mkdir(parents=True)
    (folder / "Kinds.msg").write_text(
        'bool flag true\nbyte b\nchar c\nint64 big 42\nfloat32 f\nstring name "robot"\n'
        "string<=8 short\nwstring w\nint32[<=3] few\nuint8[] data\nbool[2] pair\n"
        "builtin_interfaces/Duration wait\nfloat64 PI=3.5\nstring HELLO=hi\nbool ON=True\n"
    )
    graph = Graph(TypeRegistry(interface_dirs=[tmp_path]), clock=clock)
    install_rosapi(graph)
    [kinds, duration] = call(
        connect(graph, "c"), "/rosapi/message_details", type="demo_msgs/Kinds"
    )["typedefs"]
    expected = typedef(
        "demo_msgs/Kinds",
        flag=["boolean", -1, "True"],
        b=["octet", -1, "0"],
        c=["uint8", -1, "0"],
        big=["int64", -1, "42"],
        f=["float", -1, "0.0"],
        name=["string", -1, "robot"],
        short=["string<8>", -1, ""],
        w=["wstring", -1, ""],
        few=["int32", 0, "[]"],
        data=["uint8", 0, "[]"],
        pair=["boolean", 2, "[]"],
        wait=["builtin_interfaces/Duration", -1, "{}"],
    )
    expected["constnames"] = ["PI", "HELLO", "ON"]
    expected["constvalues"] = ["3.5", "hi", "True"]
    assert kinds == expected
    assert duration["type"] == "builtin_interfaces/Duration"


def test_service_request_and_response_details(client: Peer) -> None:
    for spelling in ("std_srvs/SetBool", "std_srvs/srv/SetBool"):
        assert call(client, "/rosapi/service_request_details", type=spelling) == {
            "typedefs": [typedef("std_srvs/SetBool_Request", data=["boolean", -1, "False"])]
        }
    assert call(client, "/rosapi/service_response_details", type="std_srvs/SetBool") == {
        "typedefs": [
            typedef(
                "std_srvs/SetBool_Response",
                success=["boolean", -1, "False"],
                message=["string", -1, ""],
            )
        ]
    }


def test_action_goal_result_and_feedback_details(client: Peer) -> None:
    fib = "example_interfaces/action/Fibonacci"
    assert call(client, "/rosapi/action_goal_details", type=fib) == {
        "typedefs": [typedef("example_interfaces/Fibonacci_Goal", order=["int32", -1, "0"])]
    }
    assert call(client, "/rosapi/action_result_details", type=fib) == {
        "typedefs": [typedef("example_interfaces/Fibonacci_Result", sequence=["int32", 0, "[]"])]
    }
    assert call(client, "/rosapi/action_feedback_details", type=fib)["typedefs"] == [
        typedef("example_interfaces/Fibonacci_Feedback", sequence=["int32", 0, "[]"])
    ]


@pytest.mark.parametrize(
    ("service", "type_name", "reason"),
    [
        ("/rosapi/message_details", "nope_msgs/Nope", "nope_msgs/msg/Nope"),
        ("/rosapi/message_details", "bad type", "bad type"),
        ("/rosapi/service_request_details", "std_srvs/Nope", "std_srvs/srv/Nope"),
        ("/rosapi/action_goal_details", "std_srvs/Nope", "std_srvs/action/Nope"),
    ],
)
def test_unknown_types_fail_the_call_with_a_reason(
    client: Peer, service: str, type_name: str, reason: str
) -> None:
    reply = call_raw(client, service, type=type_name)
    assert reply["result"] is False
    assert isinstance(reply["values"], str)
    assert reply["values"].startswith(f"service {service} failed: ")
    assert reason in reply["values"]
