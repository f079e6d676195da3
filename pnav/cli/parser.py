"""The ``pnav`` command line's parser: every command and its options (the work each does is
pnav/cli/program.py's dispatch, and the modules it names)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import cast

from pnav.bench.faults_cli import add_faults_parser
from pnav.bench.nav.worlds_cli import add_worlds_parser
from pnav.cli.dashboard_options import add_dashboard_options
from pnav.cli.learn_command import add_learn_parser
from pnav.cli.options import (
    GOAL_M,
    MAX_TOL_M,
    PROCESSES_HELP,
    Parser,
    coordinate,
    count,
    heading_deg,
    heading_tolerance_deg,
    model_option,
    not_negative,
    port,
    positive,
    processes_list,
    processes_option,
    record_option,
    record_parser,
    robot_link_options,
    stack_options,
    strategy_code,
    through,
    tolerance,
)
from pnav.cli.zone_command import add_zone_parser


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(prog="pnav", description="proactive-nav: rule-based robot navigation")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    up = commands.add_parser("up", help="run the whole stack until Ctrl-C")
    stack_options(up)
    processes_option(up)
    up.add_argument("--data-dir", type=Path, help="keep Postgres data here (default: fresh)")
    up.add_argument("--zenoh-port", type=port, default=7447, help="router port (7447)")
    up.add_argument("--log-dir", type=Path, help="service logs (default: a temp dir)")
    up.add_argument("--quiet", action="store_true", help="do not echo the services' logs")
    up.add_argument(
        "--replicas",
        action="append",
        metavar="SERVICE=N",
        help="run N processes of a scenario service that split the robots, e.g. "
        "controller=3 (repeatable, or comma-separated)",
    )
    up.add_argument(
        "--lockstep",
        action="store_true",
        help="the sim steps only when the stack is quiet (PNAV_LOCKSTEP, docs/SIM.md): "
        "with --rate max, the same world and seed give the same run, loaded or not",
    )
    up.add_argument(
        "--replace",
        action="append",
        metavar="SERVICE=COMMAND",
        help="run COMMAND instead of a scenario service, with the same environment, e.g. "
        "controller='python -m examples.sql_controller' (docs/SWAP.md; repeatable)",
    )
    add_dashboard_options(up, 8080)
    robot_link_options(up)
    up.add_argument(
        "--no-sim",
        action="store_true",
        help="real robots on the ROS 2 link: run no pybullet sim; the world file only "
        "announces the robots, map and stations (needs --robot-link ros2 and a "
        "--ros-link-file with clock: ros; docs/ROS2.md)",
    )

    record_option(up)

    goal = commands.add_parser(
        "goal",
        help="send a robot to X Y, facing --yaw, or through a route (replaces its goal)",
    )
    goal.add_argument("x", nargs="?", type=coordinate, help=f"metres, within +-{GOAL_M:.0f}")
    goal.add_argument("y", nargs="?", type=coordinate, help=f"metres, within +-{GOAL_M:.0f}")
    goal.add_argument("--robot", help="robot id (needed when there are several)")
    goal.add_argument(
        "--tolerance", type=tolerance, help=f"metres, in (0, {MAX_TOL_M:.0f}] (default 0.15)"
    )
    goal.add_argument(
        "--yaw",
        type=heading_deg,
        metavar="DEG",
        help="the heading to stop at, DEGREES in [-180, 180] in the map frame (0: +x, 90: +y; "
        "the goal row holds it in radians); the robot turns in place to it once there",
    )
    goal.add_argument(
        "--yaw-tolerance",
        type=heading_tolerance_deg,
        metavar="DEG",
        help="the heading holds within this many DEGREES, in (0, 180] (default 5.73: 0.1 rad)",
    )
    goal.add_argument(
        "--through",
        type=through,
        metavar='"x,y[,yaw]; ..."',
        help="a route instead of X Y: the poses to drive through in order (metres, yaw in "
        "DEGREES), the last one the goal's; at most 1000 waypoints before it",
    )
    goal.add_argument(
        "--stop-at-waypoints",
        action="store_true",
        help="halt at every waypoint of --through (default: pass through; a waypoint with a "
        "yaw is always halted at and turned to)",
    )

    strategy = commands.add_parser("strategy", help="switch strategy (GOTO_AVOID, ...)")
    strategy.add_argument("code", type=strategy_code)
    strategy.add_argument("--robot", help="robot id (default: every robot)")

    cancel = commands.add_parser("cancel", help="cancel the active goal")
    cancel.add_argument("--robot", help="robot id (default: every robot)")

    status = commands.add_parser("status", help="a live table per robot")
    status.add_argument("--once", action="store_true", help="print once and exit")

    commands.add_parser("down", help="stop the stack started by `pnav up`")

    env = commands.add_parser(
        "env",
        help="print the exports that join the running stack as ROLE "
        '(eval "$(pnav env controller)")',
    )
    env.add_argument("role", nargs="?", default="user", help="a service's name, or user (default)")

    migrate = commands.add_parser(
        "migrate", help="apply the contract to PNAV_DATABASE_URL (waits for the server)"
    )
    migrate.add_argument(
        "--wait", type=not_negative, default=60.0, help="seconds to wait for Postgres"
    )
    migrate.add_argument(
        "--roles",
        action="store_true",
        help="also create one role per service (passwords from PNAV_DB_PASSWORD_*) and grant "
        "each what CONTRACT.md allows; needs the server's superuser",
    )
    secrets_parser(commands)

    demo = commands.add_parser("demo", help="the demo mission (see README)")
    demo.add_argument("--json", metavar="FILE", help="also write the summary as JSON")
    demo.add_argument("--rate", default=None, help="sim rate (default: the demo's own)")
    record_option(demo)
    record_parser(cast("argparse._SubParsersAction[argparse.ArgumentParser]", commands))
    add_dashboard_options(demo, None)
    model_option(demo)
    robot_link_options(demo)
    processes_option(demo)

    bench = commands.add_parser("bench", help="benchmarks: print figures and JSON")
    benches = bench.add_subparsers(dest="bench", metavar="BENCH", required=True)
    engine = benches.add_parser("engine", help="engine rules/s and wake-up latency")
    engine.add_argument("--json", metavar="FILE", help="write the figures as JSON ('-': stdout)")
    engine.add_argument("--seconds", type=positive, default=3.0, help="throughput run length")
    engine.add_argument(
        "--notifications", type=count, default=1000, help="notifications for the latency run"
    )
    startup = benches.add_parser("startup", help="start-up time to first command, and memory")
    startup.add_argument("--json", metavar="FILE", help="write the figures as JSON ('-': stdout)")
    startup.add_argument("--runs", type=count, default=3, help="how many start-ups to time")
    processes_option(startup)
    latency = benches.add_parser(
        "latency", help="sense-to-act latency by stage, CPU and memory per process"
    )
    latency.add_argument(
        "--robots",
        default="1,10,50",
        help="robot counts, one run each (comma-separated, default 1,10,50)",
    )
    latency.add_argument("--hz", type=positive, default=20.0, help="lidar and odometry rate")
    latency.add_argument(
        "--seconds", type=positive, default=30.0, help="sim seconds measured per run (default 30)"
    )
    latency.add_argument(
        "--replicas",
        action="append",
        metavar="N|SERVICE=N",
        help="replicas: N of every scenario service, or SERVICE=N (repeatable)",
    )
    latency.add_argument(
        "--robot-link",
        default="native",
        metavar="LINK[,LINK]",
        help="the robots' wire, one run per link and robot count: native, ros2 or both "
        "(native,ros2: the ROS 2 link beside the native one in one report; default native)",
    )
    latency.add_argument("--json", metavar="FILE", help="write the figures as JSON ('-': stdout)")
    latency.add_argument(
        "--processes",
        type=processes_list,
        metavar="LAYOUT[,LAYOUT]",
        help="the stack's layout, one run per layout and size: auto, composed or separate "
        "(composed,separate: both in one report, with the price of separate processes); "
        "default PNAV_PROCESSES or auto. " + PROCESSES_HELP,
    )
    latency.add_argument(
        "--no-floor",
        action="store_true",
        help="skip the design's floor (python -m pnav.bench.chain, 20 Hz) run after each size",
    )
    nav = benches.add_parser(
        "nav",
        help="navigation: success, SPL and BARN score of every strategy/planner combo per world",
        description="Runs the whole stack (sim at --rate max, in lockstep with it) in every "
        "world of a suite with every shipped strategy/planner combination, one episode per "
        "world, combo and run. The shipped suite with the first 4 combos (GOTO_AVOID, "
        "GOTO_DIRECT) is 240 episodes, about 42 min on 2 cores; the 6 combos with GOTO_FAST, "
        "about 1 h (times --runs, twice with --monolith): --levels, --worlds and --combos "
        "run a subset.",
    )
    nav.add_argument(
        "--suite", type=Path, default=Path("worlds/barn"), help="suite folder (worlds/barn)"
    )
    nav.add_argument("--runs", type=count, default=1, help="runs per world and combo, seed = run")
    nav.add_argument(
        "--model",
        metavar="NAME|FILE",
        help="run and score every world with this robot model (OT at its top speed); "
        "default: each world's own (worlds/barn: the Burger)",
    )
    nav.add_argument("--levels", help="only these levels, comma-separated (e.g. easy,medium)")
    nav.add_argument(
        "--worlds", metavar="N|NAMES", help="the first N worlds of each level, or these names"
    )
    nav.add_argument(
        "--combos", help="e.g. GOTO_AVOID/turn_then_move,GOTO_DIRECT (default: all shipped)"
    )
    nav.add_argument(
        "--monolith",
        action="store_true",
        help="also run each episode in the monolith (pnav.monolith) and compare the cost",
    )
    nav.add_argument(
        "--pacing",
        choices=("lockstep", "lag"),
        default="lockstep",
        help="lockstep (default): the sim steps only when the stack is quiet, so the same "
        "world and seed give the same run, loaded or not; lag: decisions at most 0.1 s of "
        "sim time stale (faster, not repeatable)",
    )
    nav.add_argument(
        "--in-process",
        action="store_true",
        help="run the stack episodes in this process instead of a worker replaced every 20 "
        "(saves ~1 s per 20 episodes; this process then grows ~20 MB per episode)",
    )
    nav.add_argument("--json", metavar="FILE", help="every run and the summaries ('-': stdout)")
    nav.add_argument(
        "--report", type=Path, metavar="DIR", help="write DIR/README.md, a PNG per run, DIR/logs"
    )
    nav.add_argument(
        "--compare", type=Path, metavar="FILE", help="compare each run with an earlier --json"
    )
    processes_option(nav)
    nav.add_argument(
        "--keep-db",
        type=Path,
        metavar="DIR",
        help="keep each stack episode's database (every row of the run) in DIR/WORLD__COMBO__RUN "
        "for `pnav learn dataset --db-dir` (docs/LEARNING.md)",
    )
    add_faults_parser(benches, positive)
    processes_option(benches.choices["faults"])
    # _SubParsersAction is invariant in its parser class; ours only makes Parser ones
    add_worlds_parser(cast("argparse._SubParsersAction[argparse.ArgumentParser]", commands))
    add_zone_parser(cast("argparse._SubParsersAction[argparse.ArgumentParser]", commands))
    add_learn_parser(cast("argparse._SubParsersAction[argparse.ArgumentParser]", commands))
    return parser


def secrets_parser(commands: argparse._SubParsersAction[Parser]) -> None:
    secrets = commands.add_parser(
        "secrets", help="write random passwords for docker compose (.env, zenoh-users.txt)"
    )
    secrets.add_argument(
        "--dir", type=Path, default=Path("deploy"), help="where to write them (default: deploy)"
    )
    secrets.add_argument("--force", action="store_true", help="replace existing files")
