"""The ROS 2 -> Zenoh mapping against rmw_zenoh's own examples (ros2/rmw_zenoh, docs/design.md,
"Topic and Service name mapping to Zenoh key expressions" and "Graph Cache"), and the Jazzy
type hashes against the values published elsewhere."""

from __future__ import annotations

import pytest

from common import ros2types
from common.contract import rmw_zenoh as rz

STRING_HASH = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
ADD_TWO_INTS_HASH = "RIHS01_e118de6bf5eeb66a2491b5bda11202e7b68f198d6f67922cf30364858239c81a"


def test_topic_keys_are_the_design_documents_examples() -> None:
    assert (
        rz.topic_key(0, "/chatter", "std_msgs/msg/String", STRING_HASH)
        == f"0/chatter/std_msgs::msg::dds_::String_/{STRING_HASH}"
    )
    assert (
        rz.topic_key(
            0, rz.fully_qualified("/robot1", "chatter"), "std_msgs/msg/String", STRING_HASH
        )
        == f"0/robot1/chatter/std_msgs::msg::dds_::String_/{STRING_HASH}"
    )
    assert (
        rz.topic_key(2, "add_two_ints", "example_interfaces/srv/AddTwoInts", ADD_TWO_INTS_HASH)
        == f"2/add_two_ints/example_interfaces::srv::dds_::AddTwoInts_/{ADD_TWO_INTS_HASH}"
    )


def test_liveliness_tokens_are_the_design_documents_examples() -> None:
    listener = rz.NodeName(2, "aac3178e146ba6f1fc6e6a4085e77f21", 0, "", "listener")
    assert (
        rz.node_token(listener) == "@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/0/NN/%/%/listener"
    )
    sub = rz.entity_token(
        listener,
        10,
        rz.SUBSCRIPTION,
        "chatter",
        "std_msgs/msg/String",
        STRING_HASH,
        rz.QoS(depth=10),
    )
    assert sub == (
        "@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/10/MS/%/%/listener/%chatter/"
        f"std_msgs::msg::dds_::String_/{STRING_HASH}/::,10:,:,:,,"
    )
    talker = rz.NodeName(2, "8b20917502ee955ac4476e0266340d5c", 0, "/", "talker")
    pub = rz.entity_token(
        talker, 10, rz.PUBLISHER, "/chatter", "std_msgs/msg/String", STRING_HASH, rz.QoS(depth=7)
    )
    assert pub == (
        "@ros2_lv/2/8b20917502ee955ac4476e0266340d5c/0/10/MP/%/%/talker/%chatter/"
        f"std_msgs::msg::dds_::String_/{STRING_HASH}/::,7:,:,:,,"
    )
    server = rz.NodeName(2, "f9980ee0495eaafb3e38f0d19e2eae12", 0, "", "add_two_ints_server")
    srv = rz.entity_token(
        server,
        10,
        rz.SERVICE_SERVER,
        "add_two_ints",
        "example_interfaces/srv/AddTwoInts",
        ADD_TWO_INTS_HASH,
        rz.QoS(depth=10),
    )
    assert srv == (
        "@ros2_lv/2/f9980ee0495eaafb3e38f0d19e2eae12/0/10/SS/%/%/add_two_ints_server/"
        f"%add_two_ints/example_interfaces::srv::dds_::AddTwoInts_/{ADD_TWO_INTS_HASH}/::,10:,:,:,,"
    )


def test_a_token_parses_back_to_what_made_it() -> None:
    node = rz.NodeName(0, "5155eea6c66a84e3f86f284a79f26f6c", 3, "/robot1", "pnav_bridge")
    token = rz.entity_token(
        node, 7, rz.PUBLISHER, "cmd_vel", ros2types.TWIST, "RIHS01_" + "a" * 64, rz.RELIABLE
    )
    parsed = rz.parse_token(token)
    assert (parsed.kind, parsed.namespace, parsed.node, parsed.topic, parsed.type_name) == (
        rz.PUBLISHER,
        "/robot1",
        "pnav_bridge",
        "/robot1/cmd_vel",
        ros2types.TWIST,
    )
    assert rz.parse_token(rz.node_token(node)).kind == rz.NODE
    with pytest.raises(ValueError):
        rz.parse_token("@ros2_lv/0/abc/0/0/XX/%/%/n")


def test_non_default_qos_fields_are_written_and_defaults_left_empty() -> None:
    assert rz.QoS().chunk() == "::,:,:,:,,"
    assert rz.SENSOR_DATA.chunk() == "2::,5:,:,:,,"
    assert rz.LATCHED.chunk() == ":1:,1:,:,:,,"


@pytest.mark.parametrize(
    ("namespace", "name", "fqn"),
    [
        ("", "scan", "/scan"),
        ("/", "scan", "/scan"),
        ("robot1", "scan", "/robot1/scan"),
        ("/robot1/", "scan", "/robot1/scan"),
        ("/robot1", "/tf", "/tf"),
        ("/a/b", "c/d", "/a/b/c/d"),
    ],
)
def test_names_are_qualified_as_ros_does(namespace: str, name: str, fqn: str) -> None:
    assert rz.fully_qualified(namespace, name) == fqn


@pytest.mark.parametrize("bad", ["", "1scan", "sc an", "scan/", "a//b", "~/scan", "scan%"])
def test_names_ros_refuses_are_refused(bad: str) -> None:
    with pytest.raises(ValueError):
        rz.fully_qualified("/", bad)


def test_an_attachment_is_33_little_endian_bytes_and_round_trips() -> None:
    gid = bytes(range(16))
    data = rz.Attachment(5, 1_700_000_000_123_456_789, gid).encode()
    assert len(data) == 33
    assert data[:8] == (5).to_bytes(8, "little")
    assert data[8:16] == (1_700_000_000_123_456_789).to_bytes(8, "little")
    assert data[16] == 16 and data[17:] == gid
    assert rz.Attachment.decode(data) == rz.Attachment(5, 1_700_000_000_123_456_789, gid)
    for bad in (data[:20], data + b"\0", data[:16] + b"\x11" + gid):
        with pytest.raises(ValueError):
            rz.Attachment.decode(bad)


def test_gids_are_stable_and_distinct() -> None:
    assert rz.gid_of("a") == rz.gid_of("a") != rz.gid_of("b")
    assert len(rz.gid_of("a")) == 16


# Jazzy's hashes of the types the link speaks. Where the expected strings come from:
# std_msgs/String: rmw_zenoh docs/design.md; geometry_msgs/Twist: `ros2 topic info -v
# /cmd_vel` as printed in the ROS 2 Jazzy documentation; the others: the type tables of
# independent rmw_zenoh clients (ros-z, zenoh-ros2-sdk's checks) and `ros2 topic info -v`
# output published for Jazzy robots.
JAZZY_HASHES = {
    "std_msgs/msg/String": STRING_HASH,
    ros2types.TWIST: "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a",
    ros2types.LASER_SCAN: "RIHS01_64c191398013af96509d518dac71d5164f9382553fce5c1f8cca5be7924bd828",
    ros2types.ODOMETRY: "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0",
    ros2types.PATH: "RIHS01_1957a5bb3cee5da65c4e52e52b65a93df227efce4c20f8458b36e73066ca334b",
}


@pytest.mark.parametrize(("name", "expected"), sorted(JAZZY_HASHES.items()))
def test_jazzy_type_hashes_match_rmw_zenoh(name: str, expected: str) -> None:
    assert ros2types.ros_type(name).hash == expected


def test_the_cmd_vel_key_of_a_namespaced_robot() -> None:
    twist = ros2types.ros_type(ros2types.TWIST)
    key = rz.topic_key(0, rz.fully_qualified("/nucleo", "cmd_vel"), twist.name, twist.hash)
    assert key == (
        "0/nucleo/cmd_vel/geometry_msgs::msg::dds_::Twist_/"
        "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a"
    )


def test_cdr_round_trips_a_scan() -> None:
    scan = ros2types.message(
        ros2types.LASER_SCAN,
        header=ros2types.header(12.25, "base_scan"),
        angle_min=0.0,
        angle_max=1.0,
        angle_increment=0.5,
        time_increment=0.0,
        scan_time=0.2,
        range_min=0.1,
        range_max=3.5,
        ranges=__import__("numpy").array([1.0, 2.0, 3.0], dtype="float32"),
        intensities=__import__("numpy").zeros(0, dtype="float32"),
    )
    data = ros2types.encode(ros2types.LASER_SCAN, scan)
    assert data[:4] == b"\x00\x01\x00\x00"  # CDR, little-endian
    back = ros2types.decode(ros2types.LASER_SCAN, data)
    assert ros2types.seconds_of(back.header.stamp) == 12.25
    assert list(back.ranges) == [1.0, 2.0, 3.0]
