"""The sim's side of the benchmark: the world it serves and the sensors it publishes."""

from __future__ import annotations

import math
import time
from collections import defaultdict
from typing import Any

import zenoh

from common import bus
from common.contract import keys


def world(robots: list[str]) -> dict[str, Any]:
    return {
        "name": "bench",
        "map": {
            "resolution": 0.05,
            "origin": [0.0, 0.0, 0.0],
            "width": 200,
            "height": 200,
            "grid": bytes(200 * 200),
            "source": "bench",
        },
        "robots": [{"robot_id": r, "x": 1.0, "y": 1.0, "yaw": 0.0} for r in robots],
        "charging_stations": [],
    }


def odom(seq: int) -> dict[str, Any]:
    t = seq / 30
    return {"stamp": t, "seq": seq, "x": t, "y": 0.5, "yaw": 0.1, "linear": 0.2, "angular": 0.0}


def scan(seq: int) -> dict[str, Any]:
    ranges = [1.0 + (i % 90) / 100 if i % 7 else math.inf for i in range(360)]
    return {
        "stamp": seq / 5,
        "seq": seq,
        "angle_min": 0.0,
        "angle_increment": math.tau / 360,
        "range_min": 0.12,
        "range_max": 3.5,
        "ranges": ranges,
    }


class Player:
    """Publishes sensors as the sim would and records when each message left."""

    def __init__(self, session: zenoh.Session, robots: list[str]) -> None:
        self.session = session
        self.robots = robots
        # BLOCK, unlike the sim's DROP: the burst must measure the bridge, not lose samples
        # in this process's own queues
        self.pubs = {
            (r, t): session.declare_publisher(
                keys.robot_key(r, t), congestion_control=zenoh.CongestionControl.BLOCK
            )
            for r in robots
            for t in (keys.ODOM, keys.SCAN)
        }
        # (topic, robot, seq) -> (monotonic, wall) send time
        self.sent: dict[tuple[str, str, int], tuple[float, float]] = {}
        self.seq: dict[tuple[str, str], int] = defaultdict(int)

    def publish(self, robot: str, topic: str) -> None:
        seq = self.seq[(topic, robot)]
        self.seq[(topic, robot)] = seq + 1
        payload = bus.pack(odom(seq) if topic == keys.ODOM else scan(seq))
        self.sent[(topic, robot, seq)] = (time.monotonic(), time.time())
        self.pubs[(robot, topic)].put(payload)

    def steady(self, seconds: float, odom_hz: float = 30.0, scan_hz: float = 5.0) -> None:
        start = time.monotonic()
        next_at = {keys.ODOM: start, keys.SCAN: start}
        period = {keys.ODOM: 1 / odom_hz, keys.SCAN: 1 / scan_hz}
        while time.monotonic() - start < seconds:
            topic = min(next_at, key=lambda t: next_at[t])
            delay = next_at[topic] - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            for robot in self.robots:
                self.publish(robot, topic)
            next_at[topic] += period[topic]

    def burst(self, n: int) -> None:
        for _ in range(n):
            self.publish(self.robots[0], keys.ODOM)
