"""The faults ``pnav bench faults`` injects, one per mission, and the missions it runs.

Each fault is data: what it does (``kind``), to what (``target``), for how long. The
injections themselves are in inject.py.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from common.errors import UsageError
from pnav.run.launcher import resolve_world

SERVICES = ("sim", "bridge", "strategy", "planner", "controller", "decision")

# world -> the goal of the mission every fault interrupts: a few metres, past obstacles
MISSIONS: dict[str, tuple[float, float]] = {
    "warehouse": (6.0, 1.0),  # from (1.0, 2.5): round the first rack, along the south aisle
    "cluttered_room": (4.8, 5.6),
}


@dataclass(frozen=True)
class Fault:
    name: str
    # kill | postgres | freeze | cut | spoof | cmd_vel | rogue | forge | cli | goal | theft |
    # dashboard | stall | tablelock
    kind: str
    what: str  # for the report
    target: str = ""  # the service concerned
    seconds: float = 0.0  # how long it lasts
    argv: tuple[str, ...] = ()  # cli: the `pnav goal` arguments
    goal: str = ""  # goal: "outside" the map or "obstacle" (inside one)


def catalogue() -> tuple[Fault, ...]:
    kills = tuple(
        Fault(f"kill-{s}", "kill", f"kill -9 of the {s} (the supervisor restarts it)", s)
        for s in SERVICES
    )
    bad_goals = tuple(
        Fault(name, "cli", f"pnav goal {' '.join(argv)}", argv=argv)
        for name, argv in (
            ("goal-nan", ("nan", "1")),
            ("goal-inf", ("inf", "1")),
            ("goal-1e308", ("1e308", "1")),
            ("tolerance-nan", ("1", "1", "--tolerance", "nan")),
            ("tolerance-negative", ("1", "1", "--tolerance=-1")),
        )
    )
    return (
        *kills,
        Fault("kill-postgres", "postgres", "kill -9 of the postmaster (the launcher restarts it)"),
        Fault(
            "freeze-router-3s", "freeze", "the Zenoh router stopped (SIGSTOP) for 3 s", seconds=3
        ),
        Fault("freeze-router-10s", "freeze", "the Zenoh router stopped for 10 s", seconds=10),
        Fault(
            "cut-bridge-5s",
            "cut",
            "the bridge's links cut for 5 s (its process stopped: sockets open, nothing moves)",
            "bridge",
            5,
        ),
        Fault("cut-decision-5s", "cut", "the decision service's links cut for 5 s", "decision", 5),
        Fault(
            "spoof-odom",
            "spoof",
            "a rogue Zenoh client publishes r1's odometry at its goal, 30 Hz for 3 s, "
            "without a password, then as people (the CLI's identity)",
            seconds=3,
        ),
        Fault(
            "forged-cmd-vel",
            "cmd_vel",
            "people's Zenoh identity (the CLI's) puts cmd_vel for r1 straight to the sim, "
            "full speed and a hard turn, 30 Hz for 3 s",
            seconds=3,
        ),
        Fault(
            "rogue-priority",
            "rogue",
            "a rogue writer recommends full speed ahead at priority 1000, then 99, for 5 s",
            seconds=5,
        ),
        Fault(
            "forged-images",
            "forge",
            "forged row images on r1's keys for 5 s: recommendations at priority 1000 straight "
            "ahead (as the controller) and the commands they would make (as the decision)",
            seconds=5,
        ),
        Fault(
            "lease-theft",
            "theft",
            "pnav_user tries every lock and lease call on r1's leases, round after round, 8 s",
            seconds=8,
        ),
        *bad_goals,
        Fault("goal-outside-map", "goal", "pnav goal to a point outside the map", goal="outside"),
        Fault("goal-in-obstacle", "goal", "pnav goal to a point inside a rack", goal="obstacle"),
        # attacks on the dashboard (the stack is launched with one for these)
        Fault(
            "deep-params",
            "dashboard",
            "a strategy with params nested 500 deep, through the dashboard and by INSERT",
        ),
        Fault(
            "dns-rebinding",
            "dashboard",
            "a goal POST and a websocket to the dashboard with another site's Host and Origin",
        ),
        Fault(
            "dwa-stall",
            "stall",
            "r1 switched to GOTO_FAST with dwa's heaviest params (50 x 100 samples x 50 steps, "
            "10 s horizon) for the rest of the mission",
            "controller",
            10,
        ),
        Fault(
            "table-lock",
            "tablelock",
            "pnav_user holds strategy locked (ACCESS EXCLUSIVE) and every goal row FOR UPDATE "
            "for 8 s mid-mission",
            seconds=8,
        ),
    )


def select(only: str | None) -> tuple[Fault, ...]:
    """The faults ``--only NAME,...`` names (all without it); UsageError for an unknown one."""
    every = catalogue()
    if not only:
        return every
    by_name = {f.name: f for f in every}
    names = [n.strip() for n in only.split(",") if n.strip()]
    unknown = [n for n in names if n not in by_name]
    if unknown or not names:
        raise UsageError(
            f"--only {only!r}: unknown fault(s) {', '.join(unknown) or '(none given)'}; "
            f"choose from {', '.join(by_name)}"
        )
    return tuple(by_name[n] for n in names)


def mission_goal(world: str) -> tuple[Path, tuple[float, float]]:
    """The world file and the mission's goal; UsageError for a world with no mission."""
    path = resolve_world(world)
    goal = MISSIONS.get(path.stem)
    if goal is None:
        raise UsageError(
            f"--world {world!r}: pnav bench faults has a mission for {', '.join(MISSIONS)}"
        )
    return path, goal
