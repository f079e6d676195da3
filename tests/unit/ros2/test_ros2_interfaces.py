"""Services and actions as rosidl expands them, hashed as REP-2016 does (common/ros2interfaces),
against RIHS01 values ROS 2 builds publish: rmw_zenoh's design document's AddTwoInts; the
generated type support of action_msgs and service_msgs; example_interfaces' Fibonacci
action, whose SendGoal, GetResult and FeedbackMessage exercise the whole action expansion.
Nav2's hashes are pinned as computed here: no ROS 2 build's published value was at hand."""

from __future__ import annotations

import math

import pytest
from rosbags.typesys import Stores, get_typestore

from common import ros2interfaces as ri
from common import ros2types
from common.contract import rmw_zenoh as rz
from pnav.ros2.nav2actions import distance_remaining


def _hash(value: str) -> str:
    return f"RIHS01_{value}"


PUBLISHED = {
    # rmw_zenoh, docs/design.md ("add_two_ints" service)
    "example_interfaces/srv/AddTwoInts": _hash(
        "e118de6bf5eeb66a2491b5bda11202e7b68f198d6f67922cf30364858239c81a"
    ),
    # rosidl-generated C type support of action_msgs and service_msgs (Jazzy and later)
    "action_msgs/srv/CancelGoal": _hash(
        "573d8b0a534451d7bc2ac8c5ffde8ac14b8593b7001175d0cd6516dcbeb8689a"
    ),
    "action_msgs/srv/CancelGoal_Request": _hash(
        "3d3c84653c1f96918086887e1dcb236faec88b81a5b14fd4cf4840065bcdf8af"
    ),
    "action_msgs/srv/CancelGoal_Response": _hash(
        "35e682cf3f510e83c70a82a4aac888496dedee56773bf9d8e5e0aa81f9e1c960"
    ),
    "action_msgs/srv/CancelGoal_Event": _hash(
        "178f81615ce6be41ad328211d7a56b08b00e73f41f0b8aec256b2f3ff97a5e7e"
    ),
    "service_msgs/msg/ServiceEventInfo": _hash(
        "41bcbbe07a75c9b52bc96bfd5c24d7f0fc0a08c0cb7921b3373c5732345a6f45"
    ),
    "lifecycle_msgs/srv/GetState": _hash(
        "800a0a5aae599782b02932de0caf563f6dc4e7e94b794eadde075ba2cbef9795"
    ),
    "action_msgs/msg/GoalInfo": _hash(
        "6398fe763154554353930716b225947f93b672f0fb2e49fdd01bb7a7e37933e9"
    ),
    "action_msgs/msg/GoalStatusArray": _hash(
        "6c1684b00f177d37438febe6e709fc4e2b0d4248dca4854946f9ed8b30cda83e"
    ),
    # example_interfaces/action/Fibonacci, as ROS 2 clients over rmw_zenoh key it
    "example_interfaces/action/Fibonacci_SendGoal": _hash(
        "d1a57fb2a4afe8c21e34fb10db206f16ce6729b28531141472df92277c55b557"
    ),
    "example_interfaces/action/Fibonacci_GetResult": _hash(
        "1b0de0d5d29dc955d92f546706568428632771db13ec84c15ec1c1a59f424a57"
    ),
    "example_interfaces/action/Fibonacci_FeedbackMessage": _hash(
        "c1de71afd52e49a89c53d8262366884185bc0a02f78ce051c4e46b0a7fe59bb2"
    ),
}

# computed by this module from Jazzy's nav2_msgs fields (a change here is a change on the wire)
NAV2 = {
    "nav2_msgs/action/NavigateToPose_SendGoal": _hash(
        "a4fcb3bee1bf32e21a0e541a943b221aa0826996e2c98f079b47022b256f48b5"
    ),
    "nav2_msgs/action/NavigateToPose_GetResult": _hash(
        "c407920357d566771e8882b4ef4d1f1a84ee922d609920ccd57faa6d6e391dc5"
    ),
    "nav2_msgs/action/NavigateToPose_FeedbackMessage": _hash(
        "9d1f6fa2eb975ce733b419ac2e97b134d8ff92b6478b6559feed9a50bdfd82b3"
    ),
    "nav2_msgs/action/NavigateThroughPoses_SendGoal": _hash(
        "5a590fa8e9a32b7b9c838fdf5939a2fb8858d6cfd25bdf2f2e5f0f7bbb25f52b"
    ),
    "nav2_msgs/action/NavigateThroughPoses_GetResult": _hash(
        "fdc12773de81ce69f7eeb4366702ea757d792ab5068bc461ee3b1438e66c7b36"
    ),
    "nav2_msgs/action/NavigateThroughPoses_FeedbackMessage": _hash(
        "073962415ad2a226b3de7245b142aeb414268a4d35ef1321ff2a484e2130e2b1"
    ),
}


@pytest.fixture(scope="module")
def store() -> object:
    """A Jazzy store of its own with the examples' interfaces registered as the link does."""
    typestore = get_typestore(Stores.ROS2_JAZZY)
    ri.register(typestore, ri.CANCEL_GOAL_TYPES)
    ri.register(typestore, ri.GET_STATE_TYPES)
    ri.register(
        typestore,
        ri.service(
            "example_interfaces/srv/AddTwoInts",
            (("a", "int64"), ("b", "int64")),
            (("sum", "int64"),),
        ),
    )
    ri.register(
        typestore,
        ri.action(
            "example_interfaces/action/Fibonacci",
            goal=(("order", "int32"),),
            result=(("sequence", "int32[]"),),
            feedback=(("sequence", "int32[]"),),
        ),
    )
    return typestore


@pytest.mark.parametrize(("name", "expected"), sorted(PUBLISHED.items()))
def test_hashes_are_the_ones_ros2_builds_publish(store: object, name: str, expected: str) -> None:
    assert ri.rihs01(store, name) == expected  # type: ignore[arg-type]


def test_a_char_field_hashes_as_uint8(store: object) -> None:
    # rosbags' own hash takes char as REP-2011's CHAR: every service's hash would be wrong
    event_info = "service_msgs/msg/ServiceEventInfo"
    assert store.hash_rihs01(event_info) != PUBLISHED[event_info]  # type: ignore[attr-defined]
    # a type with no char hashes the same either way
    twist = "geometry_msgs/msg/Twist"
    assert ri.rihs01(store, twist) == store.hash_rihs01(twist)  # type: ignore[arg-type, attr-defined]


@pytest.mark.parametrize(("name", "expected"), sorted(NAV2.items()))
def test_nav2_action_hashes(name: str, expected: str) -> None:
    assert ros2types.ros_type(name).hash == expected


def test_an_action_service_key_and_token_as_rmw_zenoh_names_them() -> None:
    kind = "nav2_msgs/action/NavigateToPose_SendGoal"
    key = rz.topic_key(0, "/r1/navigate_to_pose/_action/send_goal", kind, NAV2[kind])
    assert key == (
        "0/r1/navigate_to_pose/_action/send_goal/"
        f"nav2_msgs::action::dds_::NavigateToPose_SendGoal_/{NAV2[kind]}"
    )
    node = rz.NodeName(0, "ab12", 0, "", "pnav_rviz")
    token = rz.entity_token(
        node,
        3,
        rz.SERVICE_SERVER,
        "/r1/navigate_to_pose/_action/send_goal",
        kind,
        NAV2[kind],
        rz.RELIABLE,
    )
    parsed = rz.parse_token(token)
    assert parsed.kind == "SS" and parsed.type_name == kind
    assert parsed.topic == "/r1/navigate_to_pose/_action/send_goal"


def test_a_zero_message_and_its_cdr_round_trip() -> None:
    name = "nav2_msgs/action/NavigateThroughPoses_SendGoal_Request"
    msg = ros2types.default(name)
    assert len(msg.goal_id.uuid) == 16 and msg.goal.poses == []
    back = ros2types.decode(name, ros2types.encode(name, msg))
    assert back.goal.behavior_tree == "" and bytes(back.goal_id.uuid) == bytes(16)


def test_distance_remaining_follows_the_path_then_the_poses() -> None:
    path = [(0.0, 0.0), (1.0, 0.0), (2.0, 0.0)]
    # at the path's start, its target the first pose: 2 m of path, then 3 m on to the goal
    assert distance_remaining((0.0, 0.0), path, (2.0, 0.0), [(2.0, 0.0), (2.0, 3.0)]) == 5.0
    # half way along: from the point past the nearest one
    assert distance_remaining((1.0, 0.0), path, (2.0, 0.0), [(2.0, 0.0)]) == 1.0
    # no path yet: straight through the poses
    assert distance_remaining((0.0, 0.0), [], None, [(3.0, 4.0)]) == 5.0
    # the path aims at the second pose (the first already behind): the first is not counted
    far = distance_remaining((0.0, 0.0), path, (2.0, 0.0), [(-5.0, 0.0), (2.0, 0.0)])
    assert math.isclose(far, 2.0)
    assert distance_remaining((0.0, 0.0), path, None, []) == 0.0
