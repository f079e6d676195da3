"""What an injection is handed (:class:`Context`: the running stack, its router, the bench's
own runtime, the mission) and what it gives back (:class:`Injection`), for inject.py and the
attacks in their own modules."""

from __future__ import annotations

import subprocess
from dataclasses import dataclass, field

from common.config import ZenohSettings
from common.runtime import Runtime
from pnav.run.launcher import RunningStack
from pnav.run.local_stack import BusCredentials

ROBOT = "r1"
# the first seq of spoofed odometry, and the first command_id of a forged cmd_vel: above
# anything the sim or the database numbers in a mission, so what got in can be told apart
SPOOF_SEQ = 10**9
FORGED_COMMAND_ID = 10**9


@dataclass
class Context:
    stack: RunningStack
    router: subprocess.Popen[str]
    zenoh: ZenohSettings
    rt: Runtime
    goal: tuple[float, float]
    goal_id: int
    bad_goals: dict[str, tuple[float, float]]
    bus: BusCredentials  # the run's Zenoh users: a forger uses people's, a rogue a service's


@dataclass
class Injection:
    restart_s: float | None = None
    refused: str | None = None  # the door's one line, for a refused value
    exit_code: int | None = None
    follow_goal: int | None = None  # the goal the mission now follows, if it changed
    forged_believed: int | None = None  # forged messages that had an effect (spoof)
    notes: list[str] = field(default_factory=list)
    breaches: list[str] = field(default_factory=list)  # what an attack achieved: a miss
