"""ROS 2 messages -> the native sensor bodies :mod:`.messages` validates (and Twist out).

A decoded ROS 2 message becomes the same map the sim sends (CONTRACT.md, "Robot and sim"),
and then goes through the very parsers the sim's messages do: one validation, one set of
reason codes, whatever the wire. The conversions:

- LaserScan: header stamp, angle_min, angle_increment, range_min, range_max, ranges (float32
  on the wire, float64 here), each range as the contract means it (:func:`contract_ranges`:
  REP 117's NaN and infinities); ``seq`` is the publisher's attachment sequence number.
- Odometry: pose.pose position and heading, twist.twist linear.x and angular.z; composed with
  map -> odom when a localizer publishes it (:class:`MapOdom`).
- BatteryState: energy = charge x voltage, capacity = capacity (or design_capacity) x voltage,
  power drawn = -voltage x current (ROS: current is negative when discharging; 0 if
  unmeasured, NaN in ROS), percentage x 100, charging when
  power_supply_status is CHARGING. A battery without a finite capacity cannot be a battery
  row (its capacity is NOT NULL, positive): refused as ``not_finite``.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from common import ros2types
from services.bridge.sensor_payloads import NOT_FINITE, MalformedMessage

# the beams a ROS scan's ranges may hold that the contract's row has no value of (REP 117)
NAN: Final = "nan"  # an invalid measurement
TOO_CLOSE: Final = "too_close"  # -inf: something nearer than range_min
BELOW_RANGE: Final = "below_range"  # finite, < range_min: ROS says discard (LDS-01's 0.0)
BEYOND_RANGE: Final = "beyond_range"  # finite, > range_max: ROS says discard
BeamCounts = Counter[str]


def contract_ranges(
    ranges: npt.NDArray[np.float64], range_min: float, range_max: float, counts: BeamCounts
) -> npt.NDArray[np.float64]:
    """A ROS scan's ranges as the contract's row means them (CONTRACT.md, laser_scan):

    - ``+inf`` (REP 117: no return within range_max) stays ``inf``;
    - ``-inf`` (REP 117: too close to measure) reads ``range_min``, as the sim's too-close
      hits do: an obstacle there is real, ``inf`` would say "clear";
    - ``NaN`` (REP 117: an invalid measurement), and finite values outside
      [range_min, range_max] (which LaserScan says to discard), read ``inf``: the row has no
      "unknown", and a beam with no information must not stop a robot for ever (an LDS-01
      reports 0.0 for every beam without a return). Nav2's costmap ignores them the same way.

    ``counts`` gains the beams changed, per kind. A bad range_min or range_max is left for the
    parser to refuse."""
    out = ranges.copy()
    with np.errstate(invalid="ignore"):
        nan = np.isnan(ranges)
        too_close = ranges == -math.inf
        finite = np.isfinite(ranges)
        below = finite & (ranges < range_min)
        beyond = finite & (ranges > range_max)
    for kind, mask in ((NAN, nan), (TOO_CLOSE, too_close), (BELOW_RANGE, below)):
        n = int(mask.sum())
        if n:
            counts[kind] += n
    n_beyond = int(beyond.sum())
    if n_beyond:
        counts[BEYOND_RANGE] += n_beyond
    if math.isfinite(range_min):
        out[too_close] = range_min
    out[nan | below | beyond] = math.inf
    return out


def scan_body(msg: Any, seq: int, counts: BeamCounts | None = None) -> dict[str, Any]:
    range_min, range_max = float(msg.range_min), float(msg.range_max)
    ranges = contract_ranges(
        msg.ranges.astype("float64"), range_min, range_max, Counter() if counts is None else counts
    )
    return {
        "stamp": ros2types.seconds_of(msg.header.stamp),
        "seq": seq,
        "angle_min": float(msg.angle_min),
        "angle_increment": float(msg.angle_increment),
        "range_min": range_min,
        "range_max": range_max,
        "ranges": ranges.tolist(),
    }


@dataclass(frozen=True)
class MapOdom:
    """The map -> odom transform of one robot (its localizer's correction)."""

    x: float = 0.0
    y: float = 0.0
    yaw: float = 0.0

    def apply(self, x: float, y: float, yaw: float) -> tuple[float, float, float]:
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        return self.x + c * x - s * y, self.y + s * x + c * y, yaw + self.yaw


def odom_body(msg: Any, seq: int, map_odom: MapOdom | None) -> dict[str, Any]:
    pose = msg.pose.pose
    x, y, yaw = float(pose.position.x), float(pose.position.y), ros2types.yaw_of(pose.orientation)
    if map_odom is not None:
        x, y, yaw = map_odom.apply(x, y, yaw)
    return {
        "stamp": ros2types.seconds_of(msg.header.stamp),
        "seq": seq,
        "x": x,
        "y": y,
        "yaw": yaw,
        "linear": float(msg.twist.twist.linear.x),
        "angular": float(msg.twist.twist.angular.z),
    }


def battery_body(msg: Any, seq: int) -> dict[str, Any]:
    volts = float(msg.voltage)
    capacity_ah = float(msg.capacity)
    if not math.isfinite(capacity_ah) or capacity_ah <= 0:
        capacity_ah = float(msg.design_capacity)
    capacity_wh = capacity_ah * volts
    if not math.isfinite(capacity_wh) or capacity_wh <= 0:
        raise MalformedMessage(NOT_FINITE, "no finite capacity and voltage: not a battery row")
    percentage = float(msg.percentage) * 100.0
    charge = float(msg.charge)
    energy_wh = charge * volts if math.isfinite(charge) else percentage / 100.0 * capacity_wh
    current = float(msg.current)
    return {
        "stamp": ros2types.seconds_of(msg.header.stamp),
        "seq": seq,
        "energy_wh": energy_wh,
        "capacity_wh": capacity_wh,
        "percentage": percentage,
        "charging": int(msg.power_supply_status) == ros2types.POWER_SUPPLY_STATUS_CHARGING,
        "power_w": -volts * current if math.isfinite(current) else 0.0,
    }


def map_odom_of(transform: Any) -> MapOdom | None:
    """A TransformStamped's planar part, or None if any of it is not finite."""
    t, q = transform.transform.translation, transform.transform.rotation
    values = (float(t.x), float(t.y), ros2types.yaw_of(q))
    if not all(math.isfinite(v) for v in values):
        return None
    return MapOdom(*values)


def twist(linear: float, angular: float) -> Any:
    vec = "geometry_msgs/msg/Vector3"
    return ros2types.message(
        ros2types.TWIST,
        linear=ros2types.message(vec, x=linear, y=0.0, z=0.0),
        angular=ros2types.message(vec, x=0.0, y=0.0, z=angular),
    )


def twist_stamped(stamp: float, frame: str, linear: float, angular: float) -> Any:
    return ros2types.message(
        ros2types.TWIST_STAMPED,
        header=ros2types.header(max(stamp, 0.0), frame),
        twist=twist(linear, angular),
    )
