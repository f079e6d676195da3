"""ROS 2 services and actions as rosidl makes them, and the RIHS01 hash of every type.

rosbags ships Jazzy's messages but no service or action: those are defined here as data, the
fields of each ``.srv`` and ``.action``, and expanded into the types rosidl generates from
them (REP-2011, rosidl_generator_type_description):

- a service ``pkg/srv/Name`` -> ``Name_Request``, ``Name_Response``, ``Name_Event`` (the
  service-introspection event: ``info``, ``request[<=1]``, ``response[<=1]``) and ``Name``
  itself, a struct of ``request_message``, ``response_message``, ``event_message``, whose hash
  is the one in a service's key expression;
- an action ``pkg/action/Name`` -> ``Name_Goal``, ``Name_Result``, ``Name_Feedback``, the
  services ``Name_SendGoal`` (goal_id, goal -> accepted, stamp) and ``Name_GetResult``
  (goal_id -> status, result), and the topic type ``Name_FeedbackMessage`` (goal_id,
  feedback). Cancelling and the status topic use action_msgs' own types.

:func:`rihs01` hashes a registered type as REP-2016 does, with one correction to rosbags'
own ``hash_rihs01``: a ``.msg`` ``char`` is a ``uint8`` in the type description (rosidl turns
``char`` into IDL ``uint8`` before describing it), so ``service_msgs/ServiceEventInfo``'s
``char[16] client_gid``, which every service's event type holds, hashes as ``uint8[16]``.
The hashes are checked against values published by ROS 2 builds (tests/unit/ros2).
"""

from __future__ import annotations

import json
import re
from hashlib import sha256
from typing import Any, Final

from rosbags.interfaces import Nodetype
from rosbags.typesys.store import Typestore

# one field: (name, type as a .msg writes it: "int8", "string", "pkg/msg/T", "T[]",
# "T[<=1]", "T[16]"; a nested type always by its full name)
Field = tuple[str, str]
Fields = tuple[Field, ...]

UUID: Final = "unique_identifier_msgs/msg/UUID"
TIME: Final = "builtin_interfaces/msg/Time"
DURATION: Final = "builtin_interfaces/msg/Duration"
POSE_STAMPED: Final = "geometry_msgs/msg/PoseStamped"
SERVICE_EVENT_INFO: Final = "service_msgs/msg/ServiceEventInfo"
GOAL_INFO: Final = "action_msgs/msg/GoalInfo"
GOAL_STATUS_ARRAY: Final = "action_msgs/msg/GoalStatusArray"
CANCEL_GOAL: Final = "action_msgs/srv/CancelGoal"

# REP-2011's FieldType ids (type_description_interfaces/msg/FieldType)
_TYPE_IDS: Final = {
    "nested": 1,
    "int8": 2,
    "uint8": 3,
    "int16": 4,
    "uint16": 5,
    "int32": 6,
    "uint32": 7,
    "int64": 8,
    "uint64": 9,
    "float32": 10,
    "float64": 11,
    "float128": 12,
    "char": 3,  # a .msg char is IDL uint8 (rosidl_adapter), see the module's docstring
    "bool": 15,
    "byte": 16,
    "octet": 16,
    "string": 17,
    "bounded_string": 21,
}
_ARRAY, _BOUNDED, _UNBOUNDED = 48, 96, 144
_EMPTY_MEMBER: Final = "structure_needs_at_least_one_member"
_FIELD_TYPE = re.compile(r"^([A-Za-z0-9_/]+)(?:\[(<=)?(\d*)\])?$")


def service(name: str, request: Fields, response: Fields) -> dict[str, Fields]:
    """The types rosidl generates from the service ``name`` (``pkg/srv/Name`` or an action's
    ``pkg/action/Name_SendGoal``)."""
    return {
        f"{name}_Request": request,
        f"{name}_Response": response,
        f"{name}_Event": (
            ("info", SERVICE_EVENT_INFO),
            ("request", f"{name}_Request[<=1]"),
            ("response", f"{name}_Response[<=1]"),
        ),
        name: (
            ("request_message", f"{name}_Request"),
            ("response_message", f"{name}_Response"),
            ("event_message", f"{name}_Event"),
        ),
    }


def action(name: str, goal: Fields, result: Fields, feedback: Fields) -> dict[str, Fields]:
    """The types rosidl generates from the action ``name`` (``pkg/action/Name``)."""
    types = {f"{name}_Goal": goal, f"{name}_Result": result, f"{name}_Feedback": feedback}
    types |= service(
        f"{name}_SendGoal",
        (("goal_id", UUID), ("goal", f"{name}_Goal")),
        (("accepted", "bool"), ("stamp", TIME)),
    )
    types |= service(
        f"{name}_GetResult",
        (("goal_id", UUID),),
        (("status", "int8"), ("result", f"{name}_Result")),
    )
    types[f"{name}_FeedbackMessage"] = (("goal_id", UUID), ("feedback", f"{name}_Feedback"))
    return types


# action_msgs/srv/CancelGoal (Jazzy): the one cancel service of every action
CANCEL_GOAL_TYPES: Final = service(
    CANCEL_GOAL,
    (("goal_info", GOAL_INFO),),
    (("return_code", "int8"), ("goals_canceling", f"{GOAL_INFO}[]")),
)

# lifecycle_msgs/srv/GetState: what Simple Commander's waitUntilNav2Active asks a node
GET_STATE: Final = "lifecycle_msgs/srv/GetState"
GET_STATE_TYPES: Final = service(GET_STATE, (), (("current_state", "lifecycle_msgs/msg/State"),))

# nav2_msgs' actions as Jazzy's nav2_msgs defines their fields (the constants, error codes
# included, are not part of a type's hash; the codes used are in pnav/ros2/nav2actions.py)
_NAV_FEEDBACK: Final[Fields] = (
    ("current_pose", POSE_STAMPED),
    ("navigation_time", DURATION),
    ("estimated_time_remaining", DURATION),
    ("number_of_recoveries", "int16"),
    ("distance_remaining", "float32"),
)
_NAV_RESULT: Final[Fields] = (("error_code", "uint16"), ("error_msg", "string"))
NAVIGATE_TO_POSE: Final = "nav2_msgs/action/NavigateToPose"
NAVIGATE_THROUGH_POSES: Final = "nav2_msgs/action/NavigateThroughPoses"
NAV2_TYPES: Final = {
    **action(
        NAVIGATE_TO_POSE,
        goal=(("pose", POSE_STAMPED), ("behavior_tree", "string")),
        result=_NAV_RESULT,
        feedback=_NAV_FEEDBACK,
    ),
    **action(
        NAVIGATE_THROUGH_POSES,
        goal=(("poses", f"{POSE_STAMPED}[]"), ("behavior_tree", "string")),
        result=_NAV_RESULT,
        feedback=(*_NAV_FEEDBACK, ("number_of_poses_remaining", "int16")),
    ),
}


def field_desc(typ: str) -> Any:
    """A .msg field type -> rosbags' field description (a parse tree node)."""
    match = _FIELD_TYPE.match(typ)
    if match is None:
        raise ValueError(f"not a field type: {typ!r}")
    base, bounded, size = match.groups()
    inner: Any
    if "/" in base:
        inner = (Nodetype.NAME, base)
    elif base in _TYPE_IDS and base not in ("nested", "bounded_string"):
        inner = (Nodetype.BASE, (base, 0))
    else:
        raise ValueError(f"not a field type: {typ!r}")
    if "[" not in typ:
        return inner
    if bounded or not size:
        return (Nodetype.SEQUENCE, (inner, int(size or 0)))
    return (Nodetype.ARRAY, (inner, int(size)))


def register(store: Typestore, types: dict[str, Fields]) -> None:
    """Register ``types`` (name -> fields) in ``store`` (names already there, with the same
    fields, are left as they are)."""
    new: dict[str, Any] = {
        name: ([], [(field, field_desc(typ)) for field, typ in fields])
        for name, fields in types.items()
        if name not in store.fielddefs
    }
    if new:
        store.register(new)


def _field_type(desc: Any) -> tuple[int, int, int, str]:
    """(type_id, capacity, string_capacity, nested_type_name) of a rosbags field."""
    offset, capacity = 0, 0
    if desc[0] == Nodetype.ARRAY:
        (desc, capacity), offset = desc[1], _ARRAY
    elif desc[0] == Nodetype.SEQUENCE:
        desc, capacity = desc[1]
        offset = _BOUNDED if capacity else _UNBOUNDED
    if desc[0] == Nodetype.NAME:
        return offset + _TYPE_IDS["nested"], capacity, 0, desc[1]
    base, string_bound = desc[1]
    if base == "string" and string_bound:
        return offset + _TYPE_IDS["bounded_string"], capacity, int(string_bound), ""
    return offset + _TYPE_IDS[base], capacity, 0, ""


def rihs01(store: Typestore, name: str) -> str:
    """The RIHS01 hash of the registered type ``name`` (REP-2016: SHA-256 of the JSON of its
    type description and every type it refers to, sorted by name)."""
    described: dict[str, dict[str, Any]] = {}

    def describe(typ: str) -> None:
        if typ in described:
            return
        fields = store.fielddefs[typ][1] or [(_EMPTY_MEMBER, (Nodetype.BASE, ("uint8", 0)))]
        entries: list[dict[str, Any]] = []
        nested_types: list[str] = []
        for field, desc in fields:
            type_id, capacity, string_capacity, nested = _field_type(desc)
            if nested:
                nested_types.append(nested)
            entries.append(
                {
                    "name": field,
                    "type": {
                        "type_id": type_id,
                        "capacity": capacity,
                        "string_capacity": string_capacity,
                        "nested_type_name": nested,
                    },
                }
            )
        described[typ] = {"type_name": typ, "fields": entries}
        for nested in nested_types:
            describe(nested)

    describe(name)
    document = {
        "type_description": described[name],
        "referenced_type_descriptions": [d for t, d in sorted(described.items()) if t != name],
    }
    return "RIHS01_" + sha256(json.dumps(document).encode()).hexdigest()
