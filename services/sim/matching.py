"""Whether the sim's sensor publishers have subscribers (a Zenoh client drops what it puts
on a key the router knows no subscriber for)."""

from __future__ import annotations

import logging
import threading
import time
from typing import Any, Final, cast

import zenoh

from common.contract import keys
from common.log import event

log = logging.getLogger("services.sim.node")

# at start, the longest wait for a sensor subscriber before the first reading (wall s)
LISTENERS_WAIT_S: Final = 1.0

Publishers = dict[tuple[str, str], zenoh.Publisher]


def unmatched(publishers: Publishers) -> list[str]:
    """Keys of the sensor publishers Zenoh knows no subscriber for: what is put on them
    is dropped at the sim (a client's publisher filters on the router's answer)."""
    # the stubs say bool; zenoh 1.x returns a MatchingStatus with .matching
    return sorted(
        keys.robot_key(robot, topic)
        for (robot, topic), pub in publishers.items()
        if not cast(Any, pub.matching_status).matching
    )


def await_listeners(publishers: Publishers, stop: threading.Event) -> None:
    """Before the first reading, wait (at most LISTENERS_WAIT_S) until the sensor
    publishers know of a subscriber: a Zenoh client drops a publication sent before the
    router's interest reaches it, and the readings of sim time 0 would be lost to
    listeners that were there all along. Nobody listening: start anyway."""
    deadline = time.monotonic() + LISTENERS_WAIT_S
    while not stop.is_set() and time.monotonic() < deadline:
        if len(unmatched(publishers)) < len(publishers):
            return
        stop.wait(0.01)


def warn_unmatched(publishers: Publishers) -> bool:
    """Once, a world period after the start: warn if some sensor publishers found a
    subscriber and some did not. Every shipped stack hears all of a robot's topics (the
    bridge), and a stream that never flows is otherwise silent (a fault trial once saw
    no scan for 20 s while odometry and battery flowed). True: checked."""
    missing = unmatched(publishers)
    if missing and len(missing) < len(publishers):
        message = "sensor publishers without a subscriber: their readings are dropped"
        event(log, logging.WARNING, message, keys=",".join(missing))
    return True
