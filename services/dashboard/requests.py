"""The bodies the dashboard's endpoints accept, checked before anything is written.

A request that cannot be obeyed is refused at the door with :class:`Refused`: an HTTP status
and one line saying why (docs/DASHBOARD.md lists them). The bounds are the contract's own
(common.contract.limits, the CHECK constraints of migrations 3 and 11), so the page refuses
exactly what the database would, and says so in the same words as ``pnav goal``. Who may ask
at all (the Host and Origin of a request) is services.dashboard.gate's to check.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, field
from typing import Any

from common.contract import limits, zones
from common.contract.people import Pose, check_route
from common.contract.zones import Zone
from common.errors import ContractError, UsageError

_CODE = re.compile(r"^[A-Z0-9_]+$")
_SCENARIO = re.compile(r"^[A-Za-z0-9_]+$")
_JSON_STRING = re.compile(r'"(?:[^"\\]|\\.)*"')
MAX_BODY_BYTES = 64 * 1024
# how deeply a body may nest: above the params bound (+ the body object holding them), so a
# strategy whose params are a little too deep hears the params' own reason
MAX_BODY_DEPTH = limits.MAX_PARAMS_DEPTH + 8


class Refused(UsageError):
    """A request refused with HTTP ``status`` (4xx); the message is the reason."""

    def __init__(self, status: int, reason: str) -> None:
        super().__init__(reason)
        self.status = status
        self.reason = reason


def _no_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a JSON number")


def _int64(text: str) -> int:
    """A JSON integer, refused beyond 64 bits (Postgres' bigint; a browser's JSON rounds
    past 2^53 already): a 400-digit x is a mistake, not a coordinate."""
    if (
        len(text.lstrip("-")) > 19
        or not -limits.MAX_INT64 <= (value := int(text)) <= limits.MAX_INT64
    ):
        raise Refused(
            422, f"a {len(text.lstrip('-'))}-digit integer is beyond 64 bits (+-{limits.MAX_INT64})"
        )
    return value


def _float64(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        shown = text if len(text) <= 24 else f"{text[:20]}... ({len(text)} characters)"
        raise Refused(422, f"the number {shown} is beyond a 64-bit float")
    return value


def json_depth(text: str) -> int:
    """How deeply the JSON ``text`` nests (brackets outside strings), found before parsing
    it: a parser recurses once per level, and Python's gives up near 1 000 with a
    RecursionError, not a ValueError."""
    depth = deepest = 0
    for bracket in re.sub(r"[^\[\]{}]", "", _JSON_STRING.sub("", text)):
        depth += 1 if bracket in "[{" else -1
        deepest = max(deepest, depth)
    return deepest


def json_object(body: bytes, content_type: str | None = "application/json") -> dict[str, Any]:
    """The body as a JSON object; 415 unless it is sent as application/json (what a form of
    another site cannot send without asking first), 413 over MAX_BODY_BYTES, 400 for
    anything but a JSON object (NaN and Infinity included: they are not JSON, though
    Python's parser accepts them) or one nested deeper than MAX_BODY_DEPTH, 422 for a number
    beyond 64 bits."""
    media = (content_type or "").split(";")[0].strip().lower()
    if media != "application/json":
        raise Refused(415, f"send the body as application/json, not {media or 'nothing'}")
    if len(body) > MAX_BODY_BYTES:
        raise Refused(413, f"the body is over {MAX_BODY_BYTES} bytes")
    try:
        text = body.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise Refused(400, f"the body is not valid JSON: {exc}") from None
    if (depth := json_depth(text)) > MAX_BODY_DEPTH:
        raise Refused(400, f"the body nests {depth} deep, at most {MAX_BODY_DEPTH}")
    try:
        value = json.loads(
            text, parse_constant=_no_constant, parse_int=_int64, parse_float=_float64
        )
    except (ValueError, RecursionError) as exc:
        raise Refused(400, f"the body is not valid JSON: {exc}") from None
    if not isinstance(value, dict):
        raise Refused(400, f"the body must be a JSON object, got {type(value).__name__}")
    return value


def _number(body: dict[str, Any], name: str, *, required: bool) -> float | None:
    value = body.get(name)
    if value is None:
        if required:
            raise Refused(422, f"{name!r} is missing: a number of metres")
        return None
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise Refused(422, f"{name!r} must be a number, got {value!r}")
    return float(value)


def _unknown_fields(body: dict[str, Any], allowed: set[str]) -> None:
    extra = sorted(set(body) - allowed)
    if extra:
        raise Refused(422, f"unknown field(s) {', '.join(extra)}; accepted: {sorted(allowed)}")


_POSE_FIELDS = {"x", "y", "tolerance_m", "yaw", "yaw_tolerance_rad"}


def _pose(body: dict[str, Any], where: str, stop: bool = False) -> Pose:
    """A pose of the body (``where``: "" for the goal's, "waypoints[2]." for a waypoint's);
    a field that is no number is refused naming it (the bounds: :func:`check_route`)."""

    def number(name: str, required: bool = False) -> float | None:
        try:
            return _number(body, name, required=required)
        except Refused as exc:
            raise Refused(exc.status, f"{where}{exc.reason}") from None

    x, y = number("x", True), number("y", True)
    assert x is not None and y is not None
    heading = number("yaw"), number("yaw_tolerance_rad")
    return Pose(x, y, *heading, number("tolerance_m"), stop)


@dataclass(frozen=True)
class GoalRequest:
    """A goal pose (``yaw``, ``yaw_tolerance_rad``: radians) and a route's waypoints before
    it (objects of x, y, optional tolerance_m, yaw, yaw_tolerance_rad, stop)."""

    x: float
    y: float
    tolerance_m: float | None = None
    yaw: float | None = None
    yaw_tolerance_rad: float | None = None
    waypoints: tuple[Pose, ...] = ()

    @property
    def pose(self) -> Pose:
        return Pose(self.x, self.y, self.yaw, self.yaw_tolerance_rad, self.tolerance_m)

    @classmethod
    def parse(cls, body: dict[str, Any]) -> GoalRequest:
        _unknown_fields(body, {*_POSE_FIELDS, "waypoints"})
        goal = _pose(body, "")
        listed = body.get("waypoints") or []
        if not isinstance(listed, list):
            raise Refused(422, f"'waypoints' must be a list of poses, got {listed!r}"[:200])
        try:
            limits.check_waypoint_count(len(listed))
        except ContractError as exc:
            raise Refused(422, str(exc)) from None
        waypoints = []
        for i, item in enumerate(listed, start=1):
            if not isinstance(item, dict):
                raise Refused(422, f"waypoint {i} must be an object with x and y"[:200])
            extra = sorted(set(item) - {*_POSE_FIELDS, "stop"})
            if extra:
                raise Refused(422, f"waypoint {i}: unknown field(s) {', '.join(extra)}")
            stop = item.get("stop", False)
            if not isinstance(stop, bool):
                raise Refused(422, f"waypoint {i} 'stop' must be true or false, got {stop!r}")
            waypoints.append(_pose(item, f"waypoint {i} ", stop))
        try:
            check_route(goal, waypoints)
        except ContractError as exc:
            raise Refused(422, str(exc)) from None
        return cls(goal.x, goal.y, goal.tolerance_m, goal.yaw, goal.yaw_tolerance_rad,
                   tuple(waypoints))  # fmt: skip


def strategy_code(value: Any) -> str:
    if not isinstance(value, str) or not _CODE.match(value.strip().upper()):
        raise Refused(
            422, f"'code' must be a strategy code of letters, digits and _, got {value!r}"
        )
    return value.strip().upper()


@dataclass(frozen=True)
class StrategyChoice:
    code: str

    @classmethod
    def parse(cls, body: dict[str, Any]) -> StrategyChoice:
        _unknown_fields(body, {"code"})
        return cls(strategy_code(body.get("code")))


@dataclass(frozen=True)
class NewStrategy:
    """A row of the strategy table, as a person adds one."""

    code: str
    planner_scenario: str | None
    controller_scenarios: tuple[str, ...] = ()
    params: dict[str, Any] = field(default_factory=dict)
    description: str = ""

    @classmethod
    def parse(cls, body: dict[str, Any]) -> NewStrategy:
        _unknown_fields(
            body, {"code", "planner_scenario", "controller_scenarios", "params", "description"}
        )
        planner = body.get("planner_scenario") or None
        if planner is not None and not (isinstance(planner, str) and _SCENARIO.match(planner)):
            raise Refused(422, f"'planner_scenario' must be a scenario name or null: {planner!r}")
        controllers = body.get("controller_scenarios") or []
        if not isinstance(controllers, list) or not all(
            isinstance(c, str) and _SCENARIO.match(c) for c in controllers
        ):
            raise Refused(422, "'controller_scenarios' must be a list of scenario names")
        if len(set(controllers)) != len(controllers):
            raise Refused(422, "'controller_scenarios' names a scenario twice")
        description = body.get("description") or ""
        if not isinstance(description, str):
            raise Refused(422, "'description' must be text")
        code = strategy_code(body.get("code"))
        try:
            limits.check_strategy_text(code, description.strip())
        except ContractError as exc:
            raise Refused(422, str(exc)) from None
        return cls(
            code, planner, tuple(controllers), _params(body.get("params")), description.strip()
        )


def _params(value: Any) -> dict[str, Any]:
    """A JSON object within the contract's bounds (common.contract.limits.check_params)."""
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise Refused(422, f"'params' must be a JSON object, got {type(value).__name__}")
    try:
        limits.check_params(value)
    except ContractError as exc:
        raise Refused(422, str(exc)) from None
    return value


def check_scenarios(request: NewStrategy, planners: set[str], controllers: set[str]) -> None:
    """422 when a strategy names a scenario no service here can run: a typo would otherwise
    make a strategy that silently does nothing."""
    if request.planner_scenario is not None and request.planner_scenario not in planners:
        raise Refused(
            422,
            f"unknown planner scenario {request.planner_scenario!r}; "
            f"known: {', '.join(sorted(planners)) or 'none'}",
        )
    unknown = [c for c in request.controller_scenarios if c not in controllers]
    if unknown:
        raise Refused(
            422,
            f"unknown controller scenario(s) {', '.join(unknown)}; "
            f"known: {', '.join(sorted(controllers)) or 'none'}",
        )


def zone_request(body: dict[str, Any]) -> Zone:
    """A zone row as a person draws one (CONTRACT.md, zone): 422 naming the field the zone
    table would refuse, in its words (common.contract.zones)."""
    _unknown_fields(body, {"name", "kind", "xs", "ys", "max_speed_mps", "robot_id", "description"})
    name, kind, robot, description = (
        body.get("name"),
        body.get("kind"),
        body.get("robot_id"),
        body.get("description") or "",
    )
    if not isinstance(name, str) or not isinstance(kind, str):
        wrong = "name" if not isinstance(name, str) else "kind"
        raise Refused(422, f"'{wrong}' must be text, got {body.get(wrong)!r}")
    if robot is not None and not isinstance(robot, str):
        raise Refused(422, f"'robot_id' must be a robot id or null, got {robot!r}")
    if not isinstance(description, str):
        raise Refused(422, "'description' must be text")
    coordinates = []
    for axis in ("xs", "ys"):
        values = body.get(axis)
        if not isinstance(values, list) or len(values) > zones.MAX_VERTICES:
            raise Refused(
                422, f"'{axis}' must be a list of at most {zones.MAX_VERTICES} numbers (m)"
            )
        if any(isinstance(v, bool) or not isinstance(v, int | float) for v in values):
            raise Refused(422, f"'{axis}' must hold numbers only (m)")
        coordinates.append(tuple(float(v) for v in values))
    speed = _number(body, "max_speed_mps", required=False)
    zone = Zone(name, kind, coordinates[0], coordinates[1], speed, robot, description)
    try:
        zones.check_zone(zone)
    except ContractError as exc:
        raise Refused(422, str(exc)) from None
    return zone
