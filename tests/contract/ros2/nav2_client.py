"""A Nav2 action client written from the wire format alone, for the tests: what rclpy's
ActionClient on rmw_zenoh puts on Zenoh, without the server's code (no common.ros2action,
common.ros2interfaces or common.ros2node).

- the keys: ``<domain>/<action>/_action/<service or topic>/<DDS type>/<RIHS01 hash>``,
  rmw_zenoh's docs/design.md, the hashes written out below;
- a request: a Zenoh get with the CDR request as payload, target ALL_COMPLETE, and the
  33-byte attachment (sequence number, source timestamp, GID length 16, the client's GID),
  little-endian; a reply must carry the request's sequence number and the client's GID back;
- the CDR layouts: the action's implicit types, declared here field by field in .msg syntax
  under this client's own names (CDR carries no type name).
"""

from __future__ import annotations

import itertools
import os
import struct
import threading
import time
from typing import Any

import numpy as np
import zenoh
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

DOMAIN = 0
HASHES = {
    "NavigateToPose_SendGoal": "a4fcb3bee1bf32e21a0e541a943b221aa0826996e2c98f079b47022b256f48b5",
    "NavigateToPose_GetResult": "c407920357d566771e8882b4ef4d1f1a84ee922d609920ccd57faa6d6e391dc5",
    "NavigateToPose_FeedbackMessage": (
        "9d1f6fa2eb975ce733b419ac2e97b134d8ff92b6478b6559feed9a50bdfd82b3"
    ),
    "NavigateThroughPoses_SendGoal": (
        "5a590fa8e9a32b7b9c838fdf5939a2fb8858d6cfd25bdf2f2e5f0f7bbb25f52b"
    ),
    "NavigateThroughPoses_GetResult": (
        "fdc12773de81ce69f7eeb4366702ea757d792ab5068bc461ee3b1438e66c7b36"
    ),
    "NavigateThroughPoses_FeedbackMessage": (
        "073962415ad2a226b3de7245b142aeb414268a4d35ef1321ff2a484e2130e2b1"
    ),
    "CancelGoal": "573d8b0a534451d7bc2ac8c5ffde8ac14b8593b7001175d0cd6516dcbeb8689a",
    "GoalStatusArray": "6c1684b00f177d37438febe6e709fc4e2b0d4248dca4854946f9ed8b30cda83e",
    "GetState": "800a0a5aae599782b02932de0caf563f6dc4e7e94b794eadde075ba2cbef9795",
}
FEEDBACK = """geometry_msgs/PoseStamped current_pose
builtin_interfaces/Duration navigation_time
builtin_interfaces/Duration estimated_time_remaining
int16 number_of_recoveries
float32 distance_remaining
"""
LAYOUTS = {
    "wire/msg/ToPoseGoal": "geometry_msgs/PoseStamped pose\nstring behavior_tree",
    "wire/msg/ThroughGoal": "geometry_msgs/PoseStamped[] poses\nstring behavior_tree",
    "wire/msg/ToPoseSendGoal": "unique_identifier_msgs/UUID goal_id\nwire/ToPoseGoal goal",
    "wire/msg/ThroughSendGoal": "unique_identifier_msgs/UUID goal_id\nwire/ThroughGoal goal",
    "wire/msg/SendGoalReply": "bool accepted\nbuiltin_interfaces/Time stamp",
    "wire/msg/GoalId": "unique_identifier_msgs/UUID goal_id",
    "wire/msg/NavResult": "uint16 error_code\nstring error_msg",
    "wire/msg/ResultReply": "int8 status\nwire/NavResult result",
    "wire/msg/ToPoseFeedback": FEEDBACK,
    "wire/msg/ThroughFeedback": FEEDBACK + "int16 number_of_poses_remaining\n",
    "wire/msg/ToPoseFeedbackMessage": (
        "unique_identifier_msgs/UUID goal_id\nwire/ToPoseFeedback feedback"
    ),
    "wire/msg/ThroughFeedbackMessage": (
        "unique_identifier_msgs/UUID goal_id\nwire/ThroughFeedback feedback"
    ),
    "wire/msg/CancelRequest": "action_msgs/GoalInfo goal_info",
    "wire/msg/CancelReply": "int8 return_code\naction_msgs/GoalInfo[] goals_canceling",
    "wire/msg/GetStateReply": "lifecycle_msgs/State current_state",
}
# an empty request is one uint8 (rosidl's structure_needs_at_least_one_member), after CDR's header
EMPTY_REQUEST = b"\x00\x01\x00\x00\x00"
STORE = get_typestore(Stores.ROS2_JAZZY)
for _name, _text in LAYOUTS.items():
    STORE.register(get_types_from_msg(_text, _name))


def msg(name: str, **fields: Any) -> Any:
    return STORE.types[name](**fields)


def cdr(name: str, value: Any) -> bytes:
    return bytes(STORE.serialize_cdr(value, name))


def uncdr(name: str, data: bytes) -> Any:
    return STORE.deserialize_cdr(data, name)


def uuid(goal_id: bytes) -> Any:
    return msg("unique_identifier_msgs/msg/UUID", uuid=np.frombuffer(goal_id, np.uint8).copy())


def pose(x: float, y: float, yaw: float = 0.0, frame: str = "map") -> Any:
    header = msg(
        "std_msgs/msg/Header",
        stamp=msg("builtin_interfaces/msg/Time", sec=0, nanosec=0),
        frame_id=frame,
    )
    q = msg("geometry_msgs/msg/Quaternion", x=0.0, y=0.0, z=np.sin(yaw / 2), w=np.cos(yaw / 2))
    point = msg("geometry_msgs/msg/Point", x=x, y=y, z=0.0)
    body = msg("geometry_msgs/msg/Pose", position=point, orientation=q)
    return msg("geometry_msgs/msg/PoseStamped", header=header, pose=body)


class NavClient:
    """One action client of ``action`` (``/navigate_to_pose`` or ``/navigate_through_poses``)."""

    def __init__(self, session: zenoh.Session, action: str) -> None:
        self.session = session
        self.action = action.strip("/")
        self.through = self.action.endswith("navigate_through_poses")
        self.kind = "NavigateThroughPoses" if self.through else "NavigateToPose"
        self.gid = os.urandom(16)
        self._seq = itertools.count(1)
        self.feedback: list[tuple[bytes, Any]] = []
        self.statuses: list[dict[bytes, int]] = []
        self._lock = threading.Lock()
        self._subs = [
            session.declare_subscriber(self.key("feedback", "FeedbackMessage"), self._on_feedback),
            session.declare_subscriber(self.key("status", "GoalStatusArray"), self._on_status),
        ]

    def key(self, entity: str, type_suffix: str) -> str:
        if type_suffix == "CancelGoal":
            dds, digest = "action_msgs::srv::dds_::CancelGoal_", HASHES["CancelGoal"]
        elif type_suffix == "GoalStatusArray":
            dds, digest = "action_msgs::msg::dds_::GoalStatusArray_", HASHES["GoalStatusArray"]
        else:
            name = f"{self.kind}_{type_suffix}"
            dds, digest = f"nav2_msgs::action::dds_::{name}_", HASHES[name]
        return f"{DOMAIN}/{self.action}/_action/{entity}/{dds}/RIHS01_{digest}"

    def server_tokens(self) -> set[str]:
        """The kinds and names of the action's entities the graph's liveliness tokens show."""
        found = set()
        for reply in self.session.liveliness().get(f"@ros2_lv/{DOMAIN}/**", timeout=5):
            if reply.ok is None:
                continue
            parts = str(reply.ok.key_expr).split("/")
            if len(parts) == 13 and parts[9].startswith("%" + self.action.replace("/", "%")):
                found.add(f"{parts[5]} {parts[9].replace('%', '/')}")
        return found

    def call(self, entity: str, type_suffix: str, payload: bytes, timeout: float = 30.0) -> bytes:
        """One request to the action's service; the reply's payload."""
        return self.call_key(self.key(entity, type_suffix), payload, timeout)

    def navigator_state(self) -> str:
        """The label Simple Commander's waitUntilNav2Active reads (``bt_navigator/get_state``)."""
        digest = HASHES["GetState"]
        key = (
            f"{DOMAIN}/bt_navigator/get_state/lifecycle_msgs::srv::dds_::GetState_/RIHS01_{digest}"
        )
        reply = uncdr("wire/msg/GetStateReply", self.call_key(key, EMPTY_REQUEST))
        return str(reply.current_state.label)

    def call_key(self, key: str, payload: bytes, timeout: float = 30.0) -> bytes:
        """One request; the reply's payload (AssertionError if none, or not ours)."""
        seq = next(self._seq)
        attachment = struct.pack("<qqB", seq, time.time_ns(), 16) + self.gid
        replies = self.session.get(
            key,
            payload=payload,
            attachment=attachment,
            target=zenoh.QueryTarget.ALL_COMPLETE,
            timeout=timeout,
        )
        for reply in replies:
            assert reply.ok is not None, f"an error reply: {reply.err}"
            got = reply.ok.attachment
            assert got is not None, "a reply with no attachment"
            back_seq, _stamp, length = struct.unpack_from("<qqB", got.to_bytes())
            assert (back_seq, length, got.to_bytes()[17:]) == (seq, 16, self.gid)
            return reply.ok.payload.to_bytes()
        raise AssertionError(f"no reply on {key}")

    def send_goal(self, goal_id: bytes, goal: Any) -> Any:
        layout = "ThroughSendGoal" if self.through else "ToPoseSendGoal"
        request = cdr(
            f"wire/msg/{layout}", msg(f"wire/msg/{layout}", goal_id=uuid(goal_id), goal=goal)
        )
        return uncdr("wire/msg/SendGoalReply", self.call("send_goal", "SendGoal", request))

    def get_result(self, goal_id: bytes, timeout: float = 30.0) -> Any:
        request = cdr("wire/msg/GoalId", msg("wire/msg/GoalId", goal_id=uuid(goal_id)))
        reply = self.call("get_result", "GetResult", request, timeout)
        return uncdr("wire/msg/ResultReply", reply)

    def cancel(self, goal_id: bytes) -> Any:
        info = msg(
            "action_msgs/msg/GoalInfo",
            goal_id=uuid(goal_id),
            stamp=msg("builtin_interfaces/msg/Time", sec=0, nanosec=0),
        )
        request = cdr("wire/msg/CancelRequest", msg("wire/msg/CancelRequest", goal_info=info))
        return uncdr("wire/msg/CancelReply", self.call("cancel_goal", "CancelGoal", request))

    def to_pose_goal(self, x: float, y: float, yaw: float = 0.0, frame: str = "map") -> Any:
        return msg("wire/msg/ToPoseGoal", pose=pose(x, y, yaw, frame), behavior_tree="")

    def through_goal(self, poses: list[Any]) -> Any:
        return msg("wire/msg/ThroughGoal", poses=poses, behavior_tree="")

    def feedback_of(self, goal_id: bytes) -> list[Any]:
        with self._lock:
            return [f for g, f in self.feedback if g == goal_id]

    def status_of(self, goal_id: bytes) -> int | None:
        with self._lock:
            return self.statuses[-1].get(goal_id) if self.statuses else None

    def _on_feedback(self, sample: zenoh.Sample) -> None:
        layout = "ThroughFeedbackMessage" if self.through else "ToPoseFeedbackMessage"
        message = uncdr(f"wire/msg/{layout}", sample.payload.to_bytes())
        with self._lock:
            self.feedback.append((bytes(message.goal_id.uuid.tobytes()), message.feedback))

    def _on_status(self, sample: zenoh.Sample) -> None:
        array = STORE.deserialize_cdr(sample.payload.to_bytes(), "action_msgs/msg/GoalStatusArray")
        statuses = {bytes(s.goal_info.goal_id.uuid.tobytes()): s.status for s in array.status_list}
        with self._lock:
            self.statuses.append(statuses)

    def close(self) -> None:
        for sub in self._subs:
            sub.undeclare()
