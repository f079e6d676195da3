"""The bounds the contract's CHECK constraints enforce (migrations 3 and 11), for code that
wants to refuse first.

schema.sql is the authority (its CHECK constraints); these mirror it so that a tool can say
why a value is refused before the database does (tests/contract/test_refused_values.py
checks both agree at every bound). CONTRACT.md, "Refused values", says why each is what it is.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from typing import Any, Final

from common.errors import ContractError

# goal: x and y within +-100 km of the world origin (the bridge refuses odometry beyond it,
# so a goal further away could never be reached); tolerance in (0, 100] m.
GOAL_MAX_ABS_M: Final = 1.0e5
GOAL_MAX_TOLERANCE_M: Final = 100.0
# goal and goal_waypoint headings (migration 13): yaw in [-pi, pi] rad (map frame), its
# tolerance in (0, pi] rad; a yaw given without a tolerance holds within DEFAULT_YAW_TOLERANCE_RAD.
MAX_ABS_YAW_RAD: Final = math.pi
DEFAULT_YAW_TOLERANCE_RAD: Final = 0.1
# goal_waypoint: at most this many per goal (seq runs 1..MAX_WAYPOINTS, unique per goal).
MAX_WAYPOINTS: Final = 1000
# goal_waypoint.tolerance_m when none is given: a waypoint is passed, not stopped at.
DEFAULT_WAYPOINT_TOLERANCE_M: Final = 0.3

# command_recommendation and command2robot velocities.
MAX_ABS_LINEAR_MPS: Final = 10.0
MAX_ABS_ANGULAR_RPS: Final = 20.0

# command_recommendation.priority; from SAFETY_PRIORITY up only stops (linear_mps = 0).
MIN_PRIORITY: Final = 0
MAX_PRIORITY: Final = 1000
SAFETY_PRIORITY: Final = 100

# strategy.params: top-level numbers within +-this.
MAX_ABS_PARAM: Final = 1.0e6

# The largest 64-bit signed integer (Postgres bigint): no id, count or number a tool sends
# may lie beyond it (a JSON reader in most languages rounds or refuses what does).
MAX_INT64: Final = 2**63 - 1

# strategy (migration 11): params nest at most this deep (the object itself counting one:
# {"k": 1} is 1 deep, {"k": [1]} 2), are at most this many bytes as JSON text, and every
# number in them, however deep, lies within +-MAX_INT64; the code and the description are
# short. A reader walking params recursively stays far from any recursion limit.
MAX_PARAMS_DEPTH: Final = 16
MAX_PARAMS_BYTES: Final = 16384
MAX_STRATEGY_CODE_CHARS: Final = 64
MAX_STRATEGY_DESCRIPTION_CHARS: Final = 1000


def clamp(value: float, limit: float) -> float:
    """``value`` within ``[-limit, limit]``; NaN (or a NaN or negative limit) gives 0, so a
    broken number never becomes a speed. The one clamp of a velocity to a robot's limit."""
    if not limit >= 0:
        limit = 0.0
    if math.isnan(value):
        return 0.0
    result = max(-limit, min(limit, value))
    return result if math.isfinite(result) else 0.0


def check_goal(x: float, y: float, tolerance_m: float | None) -> None:
    """ContractError naming the first value the goal table would refuse, if any."""
    for name, value in (("x", x), ("y", y)):
        if not (math.isfinite(value) and abs(value) <= GOAL_MAX_ABS_M):
            raise ContractError(
                f"goal {name} must be a finite number of metres within "
                f"+-{GOAL_MAX_ABS_M:.0f}, got {value!r}"
            )
    if tolerance_m is not None and not (
        math.isfinite(tolerance_m) and 0 < tolerance_m <= GOAL_MAX_TOLERANCE_M
    ):
        raise ContractError(
            f"goal tolerance must be a finite number of metres in (0, "
            f"{GOAL_MAX_TOLERANCE_M:.0f}], got {tolerance_m!r}"
        )


def check_heading(what: str, yaw: float | None, yaw_tolerance_rad: float | None) -> None:
    """ContractError naming the first heading value (of ``what``: "goal", "waypoint 3") the
    goal and goal_waypoint tables would refuse, if any."""
    if yaw is not None and not (math.isfinite(yaw) and abs(yaw) <= MAX_ABS_YAW_RAD):
        raise ContractError(f"{what} yaw must be a finite angle in [-pi, pi] rad, got {yaw!r}")
    if yaw_tolerance_rad is None:
        return
    if yaw is None:
        raise ContractError(f"{what} yaw_tolerance_rad needs a yaw")
    if not (math.isfinite(yaw_tolerance_rad) and 0 < yaw_tolerance_rad <= MAX_ABS_YAW_RAD):
        raise ContractError(
            f"{what} yaw_tolerance_rad must be a finite angle in (0, pi] rad, "
            f"got {yaw_tolerance_rad!r}"
        )


def check_waypoint_count(count: int) -> None:
    """ContractError when a route has more waypoints than goal_waypoint holds per goal."""
    if count > MAX_WAYPOINTS:
        raise ContractError(f"waypoints: at most {MAX_WAYPOINTS} per goal, got {count}")


def json_depth(value: Any, stop_at: int | None = None) -> int:
    """How deeply objects and arrays nest in ``value`` (0 for a scalar, 1 for ``{}`` or
    ``{"k": 1}``), as schema.sql's ``jsonb_depth``: counted level by level, so a value
    nested thousands deep is measured, not recursed into; with ``stop_at``, no deeper than
    ``stop_at + 1``."""
    depth, level = 0, [value]
    while level and (stop_at is None or depth <= stop_at):
        containers = [v for v in level if isinstance(v, Mapping | list | tuple)]
        if not containers:
            break
        depth += 1
        level = [c for v in containers for c in (v.values() if isinstance(v, Mapping) else v)]
    return depth


def _scalars(value: Any) -> list[Any]:
    """Every scalar and key in ``value`` (a value already known to be shallow)."""
    out: list[Any] = []
    todo = [value]
    while todo:
        item = todo.pop()
        if isinstance(item, Mapping):
            out.extend(item.keys())
            todo.extend(item.values())
        elif isinstance(item, list | tuple):
            todo.extend(item)
        else:
            out.append(item)
    return out


def _shown(number: int | float) -> str:
    text = repr(number)
    return text if len(text) <= 30 else f"a {len(text.lstrip('-'))}-digit number"


def check_params(params: Any) -> None:
    """ContractError naming the first way the strategy table would refuse ``params`` (a
    JSON object as Python's json module reads it), if any."""
    if not isinstance(params, Mapping):
        raise ContractError(f"strategy params must be a JSON object, got {type(params).__name__}")
    depth = json_depth(params, MAX_PARAMS_DEPTH)
    if depth > MAX_PARAMS_DEPTH:
        raise ContractError(
            f"strategy params nest more than {MAX_PARAMS_DEPTH} deep (the object itself "
            "counting one)"
        )
    for key, item in params.items():
        number = isinstance(item, int | float) and not isinstance(item, bool)
        if number and not abs(item) <= MAX_ABS_PARAM:  # NaN and infinity compare false
            raise ContractError(
                f"params.{key} must be within +-{MAX_ABS_PARAM:.0e}, got {_shown(item)}"
            )
    for item in _scalars(params):
        if isinstance(item, bool) or item is None:
            continue
        if isinstance(item, int | float) and not abs(item) <= MAX_INT64:
            raise ContractError(
                f"every number in strategy params must be within +-{MAX_INT64} (64 bits), "
                f"got {_shown(item)}"
            )
        if isinstance(item, str) and "\x00" in item:
            raise ContractError("strategy params hold a NUL character, which JSON text refuses")
        if not isinstance(item, str | int | float):
            raise ContractError(f"strategy params hold a {type(item).__name__}, not JSON")
    size = len(json.dumps(params, ensure_ascii=False).encode("utf-8"))
    if size > MAX_PARAMS_BYTES:
        raise ContractError(
            f"strategy params are {size} bytes as JSON text, at most {MAX_PARAMS_BYTES}"
        )


def check_strategy_text(code: str, description: str) -> None:
    """ContractError if the strategy table would refuse ``code`` or ``description`` for
    their length (the code's letters are checked by whoever parses it)."""
    if len(code) > MAX_STRATEGY_CODE_CHARS:
        raise ContractError(
            f"a strategy code is at most {MAX_STRATEGY_CODE_CHARS} characters, got {len(code)}"
        )
    if len(description) > MAX_STRATEGY_DESCRIPTION_CHARS:
        raise ContractError(
            f"a strategy description is at most {MAX_STRATEGY_DESCRIPTION_CHARS} characters, "
            f"got {len(description)}"
        )
