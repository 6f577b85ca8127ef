"""Golden tests of the rmw_zenoh wire (rwt_zenoh.wire).

Each expectation is derived from ros2/rmw_zenoh, rmw_zenoh_cpp/src/detail/ at
rolling commit bfc065f8 (2024-10-16), file and line named in the test; the
session id in tokens and the attachment follow its Zenoh 1.x line: the id as
Zenoh prints it, and attachment_helpers.cpp (``serialize_to_zbytes``: int64,
int64, then the 16-byte GID as a Zenoh serialization sequence).
"""

from __future__ import annotations

import pytest
from rosbags.typesys import Stores, get_typestore

from rwt_zenoh.wire import (
    DEFAULT_QOS,
    INFINITE,
    PRE_2025_DEFAULT_QOS,
    Attachment,
    Durability,
    Entity,
    EntityKind,
    History,
    QoS,
    Reliability,
    RmwCompat,
    Topic,
    WireError,
    dds_type_name,
    demangle,
    gid_of,
    mangle,
    qos_from_keyexpr,
    qos_to_keyexpr,
    reply_attachment,
    ros_type_name,
    topic_keyexpr,
    zid_text,
)

STRING_HASH = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
ZID = "aac3178e146ba6f1fc6e6a4085e77f21"


def test_the_type_hash_is_rosbags_rihs01() -> None:
    # the hash rmw_zenoh puts in keys and tokens is rosidl's RIHS01 (rmw_publisher_data.cpp:60-70)
    assert get_typestore(Stores.ROS2_JAZZY).hash_rihs01("std_msgs/msg/String") == STRING_HASH


def test_dds_type_names() -> None:
    # type_support_common.cpp:32-46: "<pkg>::<kind>::dds_::<Name>_"
    assert dds_type_name("std_msgs/msg/String") == "std_msgs::msg::dds_::String_"
    assert dds_type_name("example_interfaces/srv/AddTwoInts") == (
        "example_interfaces::srv::dds_::AddTwoInts_"
    )
    assert ros_type_name("geometry_msgs::msg::dds_::Twist_") == "geometry_msgs/msg/Twist"
    with pytest.raises(WireError):
        dds_type_name("std_msgs/String")
    with pytest.raises(WireError):
        ros_type_name("std_msgs/msg/String")


def test_topic_keys() -> None:
    # liveliness_utils.cpp:74-87: domain, the name without its outer slashes, type, hash
    dds = dds_type_name("std_msgs/msg/String")
    assert topic_keyexpr(0, "/chatter", dds, STRING_HASH) == (
        f"0/chatter/std_msgs::msg::dds_::String_/{STRING_HASH}"
    )
    assert topic_keyexpr(7, "/robot/odom/", "x", "h") == "7/robot/odom/x/h"


def test_names_are_mangled_with_percent() -> None:
    # liveliness_utils.cpp:656: every "/" becomes "%"
    assert mangle("/") == "%"
    assert mangle("/robot/odom") == "%robot%odom"
    assert demangle(mangle("/a/b")) == "/a/b"


@pytest.mark.parametrize(
    ("qos", "text"),
    [
        # qos.cpp: reliable, volatile (since March 2025), keep last 42, infinite durations
        (DEFAULT_QOS, "::,:,:,:,,"),
        # liveliness_utils.cpp:237-297: only what differs from the default is written
        (QoS(durability=Durability.VOLATILE, depth=10), "::,10:,:,:,,"),
        (QoS(durability=Durability.TRANSIENT_LOCAL, depth=1), ":1:,1:,:,:,,"),
        (
            QoS(Reliability.BEST_EFFORT, Durability.VOLATILE, History.KEEP_ALL, 1, (1, 5)),
            "2::2,1:1,5:,:,,",
        ),
    ],
)
def test_qos_strings(qos: QoS, text: str) -> None:
    assert qos_to_keyexpr(qos) == text
    assert qos_from_keyexpr(text) == qos


@pytest.mark.parametrize(
    ("qos", "current", "pre_2025"),
    [
        # a plain topic: current rmw_zenoh leaves its durability empty, the older wrote 2
        (QoS(durability=Durability.VOLATILE, depth=10), "::,10:,:,:,,", ":2:,10:,:,:,,"),
        # /tf_static, /map: current rmw_zenoh writes 1, the older left it empty
        (QoS(durability=Durability.TRANSIENT_LOCAL, depth=1), ":1:,1:,:,:,,", "::,1:,:,:,,"),
    ],
)
def test_durability_defaults_per_rmw_zenoh_release(qos: QoS, current: str, pre_2025: str) -> None:
    assert qos_to_keyexpr(qos, RmwCompat.CURRENT.defaults) == current
    assert qos_to_keyexpr(qos, RmwCompat.PRE_2025.defaults) == pre_2025
    assert qos_from_keyexpr(current, RmwCompat.CURRENT.defaults) == qos
    assert qos_from_keyexpr(pre_2025, RmwCompat.PRE_2025.defaults) == qos
    # the default is the current release: an empty durability is volatile
    assert qos_from_keyexpr("::,1:,:,:,,").durability is Durability.VOLATILE
    assert qos_from_keyexpr("::,1:,:,:,,", PRE_2025_DEFAULT_QOS).durability is (
        Durability.TRANSIENT_LOCAL
    )


def test_a_token_parsed_with_the_compat_writes_back_the_same() -> None:
    token = (
        f"@ros2_lv/0/{ZID}/0/10/MP/%/%/talker/%tf_static/tf2_msgs::msg::dds_::TFMessage_/"
        f"{STRING_HASH}/::,1:,:,:,,"
    )
    old = Entity.parse(token, RmwCompat.PRE_2025)
    assert old.topic is not None
    assert old.topic.qos.durability is Durability.TRANSIENT_LOCAL
    assert old.token() == token
    assert Entity.parse(token).topic.qos.durability is Durability.VOLATILE  # type: ignore[union-attr]


def test_a_remote_gid_is_the_hash_of_the_token_as_received() -> None:
    # a peer may spell a default out (here reliability 1 and depth 42 written in full):
    # its GID, which its samples' attachments carry, hashes the text it declared
    pytest.importorskip("xxhash")
    token = (
        f"@ros2_lv/0/{ZID}/0/10/MP/%/%/talker/%chatter/std_msgs::msg::dds_::String_/"
        f"{STRING_HASH}/1:1:1,42:,:,:,,"
    )
    entity = Entity.parse(token)
    assert entity.token() != token  # this side would write the defaults empty
    assert entity.gid() == gid_of(token)
    assert entity.gid() != gid_of(entity.token())


def test_bad_qos_strings_are_refused() -> None:
    # liveliness_utils.cpp:301-360: six fields, known policies, unsigned numbers
    for text in ("1:2", "9::,:,:,:,,", "::x,:,:,:,,", "::,-1:,:,:,,", "::,:,:,:,"):
        with pytest.raises(WireError):
            qos_from_keyexpr(text)


def test_a_publisher_token() -> None:
    # liveliness_utils.cpp:395-447: admin space, domain, zid, nid, eid, kind, enclave,
    # namespace, node, then topic, type, hash and QoS; "/" alone mangles to "%"
    qos = QoS(durability=Durability.VOLATILE, depth=7)
    entity = Entity(
        0,
        ZID,
        0,
        10,
        EntityKind.PUBLISHER,
        "/",
        "talker",
        topic=Topic("/chatter", dds_type_name("std_msgs/msg/String"), STRING_HASH, qos),
    )
    assert entity.token() == (
        f"@ros2_lv/0/{ZID}/0/10/MP/%/%/talker/%chatter/std_msgs::msg::dds_::String_/"
        f"{STRING_HASH}/::,7:,:,:,,"
    )
    assert Entity.parse(entity.token()) == entity


def test_a_node_token() -> None:
    node = Entity(3, ZID, 2, 2, EntityKind.NODE, "/robot", "arm")
    assert node.token() == f"@ros2_lv/3/{ZID}/2/2/NN/%/%robot/arm"
    assert Entity.parse(node.token()) == node


@pytest.mark.parametrize(
    "token",
    [
        f"@other/0/{ZID}/0/1/NN/%/%/n",  # not the admin space
        f"@ros2_lv/0/{ZID}/0/1/XX/%/%/n",  # unknown kind
        f"@ros2_lv/0/{ZID}/0/1/MP/%/%/n",  # a publisher without its topic
        f"@ros2_lv/0/{ZID}//1/NN/%/%/n",  # an empty part
    ],
)
def test_bad_tokens_are_refused(token: str) -> None:
    # liveliness_utils.cpp:495-560
    with pytest.raises(WireError):
        Entity.parse(token)


def test_zid_text_is_zenoh_own_form_of_the_id() -> None:
    # liveliness_utils.cpp Entity::make (Zenoh 1.x line, 3411fdec): zid.to_string(), the
    # little-endian u128 in lowercase hex without leading zeros
    assert zid_text(bytes([0x21, 0x7F, 0x0A]) + bytes(13)) == "a7f21"
    assert zid_text(bytes(range(1, 17))) == "100f0e0d0c0b0a090807060504030201"


def test_zid_text_matches_zenoh_for_real_sessions() -> None:
    zenoh = pytest.importorskip("zenoh")
    from rwt_zenoh.config import ZenohOptions, make_config  # noqa: PLC0415

    config = make_config(ZenohOptions(listen=(), connect=()))
    for _ in range(16):  # random ids: bytes below 0x10 in most, a top one in some
        session = zenoh.open(config)
        try:
            zid = session.info.zid()
            assert zid_text(bytes(zid)) == str(zid)
        finally:
            session.close()


def test_the_gid_is_xxh3_128_of_the_token() -> None:
    # liveliness_utils.cpp:449-452: low 64 bits then high 64 bits, as stored on x86
    xxhash = pytest.importorskip("xxhash")
    entity = Entity(0, ZID, 0, 0, EntityKind.NODE, "/", "talker")
    digest = xxhash.xxh3_128_intdigest(entity.token().encode())
    assert entity.gid() == digest.to_bytes(16, "little")
    assert len({Entity(0, ZID, 0, i, EntityKind.NODE, "/", "n").gid() for i in range(50)}) == 50


def test_gid_of_is_the_entity_gid_of_its_token() -> None:
    pytest.importorskip("xxhash")
    entity = Entity(0, ZID, 0, 7, EntityKind.NODE, "/", "talker")
    assert gid_of(entity.token()) == entity.gid()
    assert gid_of("a") != gid_of("b")


def test_a_reply_carries_the_request_sequence_number_and_client_gid() -> None:
    # rmw_service_data.cpp send_response: the request's sequence number and writer GUID,
    # the service's own timestamp; rmw_client_data.cpp take_response reads them back
    request = Attachment(42, 1_000, bytes(range(16))).encode()
    reply = Attachment.decode(reply_attachment(request, 2_000))
    assert reply == Attachment(42, 2_000, bytes(range(16)))
    assert reply_attachment(request, 2_000).hex() == (
        "2a00000000000000"  # the request's sequence number
        "d007000000000000"  # the reply's own source timestamp (2000 ns)
        "10"  # the GID's length
        "000102030405060708090a0b0c0d0e0f"  # the client's GID
    )


def test_a_request_without_rmw_zenoh_attachment_is_answered_with_sequence_zero() -> None:
    for request in (None, b"", b"not an attachment", bytes(40)):
        reply = Attachment.decode(reply_attachment(request, 5))
        assert reply == Attachment(0, 5, bytes(16))


def test_the_attachment_bytes() -> None:
    attachment = Attachment(1, 1_700_000_000_123_456_789, bytes(range(16)))
    data = attachment.encode()
    assert data.hex() == (
        "0100000000000000"  # sequence number, int64 little endian
        "15cd853dfe9c9717"  # source timestamp, ns
        "10"  # the GID as a sequence: LEB128 length 16
        "000102030405060708090a0b0c0d0e0f"
    )
    assert Attachment.decode(data) == attachment
    with pytest.raises(WireError):
        Attachment.decode(data[:-1])


def test_the_attachment_matches_zenohs_own_serializer() -> None:
    zenoh_ext = pytest.importorskip("zenoh.ext")
    gid = bytes(range(16))
    ours = Attachment(5, -2, gid).encode()
    theirs = zenoh_ext.z_serialize((zenoh_ext.Int64(5), zenoh_ext.Int64(-2), gid)).to_bytes()
    assert ours == theirs


def test_durations_default_to_infinite() -> None:
    assert DEFAULT_QOS.deadline == DEFAULT_QOS.lifespan == INFINITE == (9223372036, 854775807)
