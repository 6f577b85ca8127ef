"""Type strings (D5, REF §4.6, §8.4 L58)."""

from __future__ import annotations

import pytest
from types_support import DATA

from rwt_graph.types import Dialect, InvalidTypeNameError, TypeRegistry, UnknownTypeError
from rwt_graph.types import registry as registry_module
from rwt_protocol.errors import GraphError

VALID_STRING_SPELLINGS = [
    "std_msgs/String",
    "std_msgs/msg/String",
    "/std_msgs/String",
    "std_msgs/String/",
    "//std_msgs//String//",
    "/std_msgs/msg/String/",
    "std_msgs///msg//String",
]


@pytest.mark.parametrize("name", VALID_STRING_SPELLINGS)
def test_irregular_but_valid_message_names_resolve_to_one_type(
    ros2: TypeRegistry, name: str
) -> None:
    mtype = ros2.message(name)
    assert mtype.name == "std_msgs/msg/String"
    assert mtype is ros2.message("std_msgs/msg/String")


@pytest.mark.parametrize(
    "name",
    [
        "",
        "/",
        "//",
        "bad",
        "/better",
        "better/",
        "std_msgs\\String",
        "std_msgs/String\\",
        "int32",
        "time",
        "duration",
        "not/better/even/still",
        "std_msgs/nope/String",
        "std_msgs/String[]",
        "std msgs/String",
        "1pkg/Type",
    ],
)
def test_invalid_message_names_raise_invalid_type_name(ros2: TypeRegistry, name: str) -> None:
    with pytest.raises(InvalidTypeNameError) as caught:
        ros2.message(name)
    assert caught.value.message == (
        f"{name!r} is not a valid type name (expected pkg/Type or pkg/msg/Type)"
    )
    assert isinstance(caught.value, GraphError)


@pytest.mark.parametrize("name", ["bad", "not/better/even/still", "std_srvs/msg/Empty", ""])
def test_invalid_service_and_action_names(ros2: TypeRegistry, name: str) -> None:
    with pytest.raises(InvalidTypeNameError, match=r"expected pkg/Type or pkg/srv/Type"):
        ros2.service(name)
    with pytest.raises(InvalidTypeNameError, match=r"expected pkg/Type or pkg/action/Type"):
        ros2.action(name.replace("msg", "srv"))


def test_unknown_class_and_unknown_package_are_distinguished(ros2: TypeRegistry) -> None:
    with pytest.raises(UnknownTypeError) as caught:
        ros2.message("std_msgs/Spool")
    assert caught.value.message == "unknown message type 'std_msgs/msg/Spool'"
    assert caught.value.package_known
    with pytest.raises(UnknownTypeError) as caught:
        ros2.message("no_such_pkg/Thing")
    assert caught.value.message == (
        "unknown message type 'no_such_pkg/msg/Thing' (no package 'no_such_pkg')"
    )
    assert not caught.value.package_known
    with pytest.raises(UnknownTypeError, match=r"^unknown service type 'rwt_test_msgs/srv/Nope'$"):
        ros2.service("rwt_test_msgs/Nope")
    with pytest.raises(UnknownTypeError, match=r"^unknown action type 'std_msgs/action/Nope'$"):
        ros2.action("std_msgs/Nope")


def test_services_and_actions_resolve_by_both_forms(ros2: TypeRegistry) -> None:
    service = ros2.service("rwt_test_msgs/AddInts")
    assert service is ros2.service("//rwt_test_msgs/srv/AddInts")
    assert service.name == "rwt_test_msgs/srv/AddInts"
    assert service.request.name == "rwt_test_msgs/srv/AddInts_Request"
    assert [f.name for f in service.response.fields] == ["sum"]
    action = ros2.action("rwt_test_msgs/action/Count")
    assert action is ros2.action("rwt_test_msgs/Count")
    assert action.feedback.name == "rwt_test_msgs/action/Count_Feedback"
    assert ros2.message("rwt_test_msgs/srv/AddInts_Response") is service.response
    assert ros2.message("rwt_test_msgs/action/Count_Goal") is action.goal


def test_canonical_name_only_validates(ros2: TypeRegistry, ros1: TypeRegistry) -> None:
    assert ros2.canonical_name("/nowhere/Thing/") == "nowhere/msg/Thing"
    assert ros2.canonical_name("a/srv/B", "srv") == "a/srv/B"
    assert ros2.canonical_name("a/B", "action") == "a/action/B"
    assert ros1.canonical_name("std_msgs/msg/String") == "std_msgs/String"
    with pytest.raises(InvalidTypeNameError):
        ros2.canonical_name("a/msg/B", "srv")


def test_ros1_names_and_part_names(ros1: TypeRegistry) -> None:
    assert ros1.message("std_msgs/msg/String").name == "std_msgs/String"
    service = ros1.service("rwt_test_msgs/srv/AddInts")
    assert service.name == "rwt_test_msgs/AddInts"
    assert service.request.name == "rwt_test_msgs/AddIntsRequest"
    assert ros1.message("rwt_test_msgs/AddIntsResponse") is service.response
    assert ros1.message("rwt_test_msgs/CountFeedback").name == "rwt_test_msgs/CountFeedback"


def test_name_listings(ros2: TypeRegistry, ros1: TypeRegistry) -> None:
    messages = ros2.message_names()
    assert "std_msgs/msg/String" in messages
    assert "rwt_test_msgs/msg/Limits" in messages
    assert messages == sorted(set(messages))
    assert "rwt_test_msgs/srv/AddInts" in ros2.service_names()
    assert "rwt_test_msgs/action/Count" in ros2.action_names()
    assert "std_msgs/Header" in ros1.message_names()
    assert "rwt_test_msgs/AddInts" in ros1.service_names()


@pytest.mark.parametrize("dialect", list(Dialect))
def test_every_listed_message_loads_and_accepts_its_default(dialect: Dialect) -> None:
    registry = TypeRegistry(dialect)
    for name in registry.message_names():
        mtype = registry.message(name)
        assert mtype.from_json(mtype.default(), now=0.0).msg == mtype.default()


def test_parts_resolve_before_their_service_or_action_is_loaded() -> None:
    registry = TypeRegistry(Dialect.ROS2, [DATA])
    request = registry.message("rwt_test_msgs/srv/AddInts_Request")
    assert request is registry.service("rwt_test_msgs/AddInts").request
    result = registry.message("rwt_test_msgs/action/Count_Result")
    assert result is registry.action("rwt_test_msgs/Count").result
    with pytest.raises(UnknownTypeError, match=r"unknown message type 'rwt_test_msgs/srv/AddInts'"):
        registry.message("rwt_test_msgs/srv/AddInts")
    ros1 = TypeRegistry(Dialect.ROS1, [DATA])
    assert ros1.message("rwt_test_msgs/CountGoal") is ros1.action("rwt_test_msgs/Count").goal
    assert (
        ros1.message("rwt_test_msgs/AddIntsRequest")
        is ros1.service("rwt_test_msgs/AddInts").request
    )
    with pytest.raises(UnknownTypeError, match=r"unknown message type 'rwt_test_msgs/NoneRequest'"):
        ros1.message("rwt_test_msgs/NoneRequest")


def test_alias_caches_are_bounded(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(registry_module, "_ALIAS_LIMIT", 0)
    registry = TypeRegistry(Dialect.ROS2, [DATA])
    assert registry.message("/std_msgs/String") is registry.message("/std_msgs/String")
    assert registry.service("rwt_test_msgs/AddInts") is registry.service("rwt_test_msgs/AddInts")
    assert registry.action("rwt_test_msgs/Count") is registry.action("rwt_test_msgs/Count")
