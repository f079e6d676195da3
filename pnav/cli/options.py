"""The ``pnav`` command line's argument types and shared options: each refuses a bad value in
one line (what is wrong, and where help is), exit 2, before anything starts."""

from __future__ import annotations

import argparse
import math
import os
from collections.abc import Callable
from pathlib import Path
from typing import NoReturn

from common.contract import limits
from common.errors import UsageError
from common.robotlink import CLOCK_ROS, load_link_file


class Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one line (what is wrong, and where help is), exit 2:
    the usage block argparse prints first buries the reason under every option."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: {message} (see `{self.prog} --help`)\n")


def _shown(text: str) -> str:
    """``text`` as a refusal quotes it: a 400-digit number is named by its length."""
    return repr(text) if len(text) <= 30 else f"{text[:20]!r}... ({len(text)} characters)"


def number(
    meaning: str, accepts: Callable[[float], bool], convert: Callable[[str], float] = float
) -> Callable[[str], float]:
    """An argparse ``type``: a number ``accepts`` holds for, else an error saying
    ``meaning`` (e.g. "a finite number of metres within +-100000")."""

    def parse(text: str) -> float:
        try:
            value = convert(text)
        except (ValueError, OverflowError):
            value = math.nan
        if not (math.isfinite(value) and accepts(value)):
            raise argparse.ArgumentTypeError(f"must be {meaning}, got {_shown(text)}")
        return value

    return parse


GOAL_M = limits.GOAL_MAX_ABS_M
MAX_TOL_M = limits.GOAL_MAX_TOLERANCE_M
coordinate = number(f"a finite number of metres within +-{GOAL_M:.0f}", lambda v: abs(v) <= GOAL_M)
tolerance = number(
    f"a finite number of metres in (0, {MAX_TOL_M:.0f}]", lambda v: 0 < v <= MAX_TOL_M
)
# headings on the command line are degrees (the goal rows hold radians)
heading_deg = number("a finite angle in degrees within [-180, 180]", lambda v: abs(v) <= 180)
heading_tolerance_deg = number("a finite angle in degrees in (0, 180]", lambda v: 0 < v <= 180)
positive = number("a finite number above 0", lambda v: v > 0)
not_negative = number("a finite number, 0 or more", lambda v: v >= 0)
percent = number("a percentage from 0 to 100", lambda v: 0 <= v <= 100)
count = number("a whole number, 1 or more", lambda v: v >= 1, int)
port = number("a port number from 1 to 65535", lambda v: 1 <= v <= 65535, int)


def through(text: str) -> list[tuple[float, float, float | None]]:
    """An argparse ``type``: a route ``"x,y[,yaw]; x,y[,yaw]; ..."`` (metres, degrees), the
    last pose the goal's; at most limits.MAX_WAYPOINTS waypoints before it. Each refusal
    names the pose (``pose 3``) and the field."""
    parts = [p.strip() for p in text.split(";")]
    if parts and not parts[-1]:
        parts.pop()  # a trailing ';'
    most = limits.MAX_WAYPOINTS + 1
    if len(parts) > most:
        raise argparse.ArgumentTypeError(
            f"at most {most} poses ({limits.MAX_WAYPOINTS} waypoints and the goal), "
            f"got {len(parts)}"
        )
    if not parts:
        raise argparse.ArgumentTypeError('needs at least one pose, "x,y[,yaw]"')
    poses: list[tuple[float, float, float | None]] = []
    for i, part in enumerate(parts, start=1):
        fields = [f.strip() for f in part.split(",")]
        if len(fields) not in (2, 3):
            raise argparse.ArgumentTypeError(
                f"pose {i} must be x,y or x,y,yaw (metres, degrees), got {_shown(part)}"
            )
        try:
            x, y = (coordinate(f) for f in fields[:2])
            yaw = heading_deg(fields[2]) if len(fields) == 3 else None
        except argparse.ArgumentTypeError as exc:
            name = ("x", "y", "yaw")[_first_bad(fields)]
            raise argparse.ArgumentTypeError(f"pose {i} {name} {exc}") from None
        poses.append((x, y, yaw))
    return poses


def _first_bad(fields: list[str]) -> int:
    """The index of the first field of a pose the checks refuse."""
    for i, text in enumerate(fields):
        check = coordinate if i < 2 else heading_deg
        try:
            check(text)
        except argparse.ArgumentTypeError:
            return i
    return 0


def strategy_code(text: str) -> str:
    """A strategy code as the strategy table spells them (upper case, ``[A-Z0-9_]+``)."""
    code = text.strip().upper()
    if not code or not all(c.isascii() and (c.isalnum() or c == "_") for c in code):
        raise argparse.ArgumentTypeError(
            "must be a strategy code of letters, digits and _ (e.g. GOTO_AVOID), "
            f"got {_shown(text)}"
        )
    if len(code) > limits.MAX_STRATEGY_CODE_CHARS:
        raise argparse.ArgumentTypeError(
            f"a strategy code is at most {limits.MAX_STRATEGY_CODE_CHARS} characters, "
            f"got {len(code)}"
        )
    return code


def robot_model(text: str) -> str:
    """An argparse ``type``: a robot model name (models/) or model file, checked now so a bad
    one is a one-line error, not a sim that exits later. A file becomes an absolute path (the
    sim may start elsewhere)."""
    from common.errors import ModelError
    from common.robotmodel import load_model, model_path

    try:
        load_model(text)
        path = model_path(text)
    except ModelError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text if path.stem == text and not Path(text).suffix else str(path.resolve())


def model_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--model",
        type=robot_model,
        metavar="NAME|FILE",
        help="robot model of every robot the world does not give one (models/*.yaml; "
        "default turtlebot3_burger)",
    )


PROCESSES_HELP = (
    "separate: one process per service; composed: strategy, planner, controller and decision "
    "in one host process (one interpreter, event loop and Zenoh session; a crash of one "
    "restarts the four); auto (default): composed on a machine of at most 4 cores "
    '(PNAV_PROCESSES, docs/ARCHITECTURE.md "Processes")'
)


PROCESSES_CHOICES = ("auto", "composed", "separate")


def processes_list(text: str) -> str:
    """``--processes`` of a command that runs every layout listed (comma-separated), as
    given once each is known."""
    names = [part.strip() for part in text.split(",")]
    if not all(name in PROCESSES_CHOICES for name in names):
        raise argparse.ArgumentTypeError(
            f"{text!r}: each layout must be one of {', '.join(PROCESSES_CHOICES)}"
        )
    return text


def processes_option(parser: argparse.ArgumentParser) -> None:
    """``--processes``: how the stack's services share processes (pnav.run.launcher)."""
    parser.add_argument("--processes", choices=PROCESSES_CHOICES, help=PROCESSES_HELP)


def apply_processes(args: argparse.Namespace) -> None:
    """``--processes`` for every stack the command starts (a benchmark's workers' too):
    PNAV_PROCESSES, which pnav.run.stack_options.StackOptions reads."""
    # a list (`pnav bench latency --processes composed,separate`) is the command's own: it
    # gives each run its layout
    if getattr(args, "processes", None) in PROCESSES_CHOICES:
        os.environ["PNAV_PROCESSES"] = args.processes


def stack_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--world", default="warehouse", help="world name or file (warehouse)")
    parser.add_argument(
        "--rate", default="1", help="sim seconds per wall second, or 'max' (default 1)"
    )
    parser.add_argument("--gui", action="store_true", help="open the pybullet window")
    parser.add_argument("--robots", type=count, help="run exactly N robots")
    parser.add_argument("--battery", type=percent, help="start charge of every robot, percent")
    model_option(parser)


def record_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--record",
        type=Path,
        metavar="FILE",
        help="record the mission into FILE as MCAP, Foxglove's schemas (docs/RECORDING.md)",
    )
    parser.add_argument(
        "--encoding",
        choices=("foxglove", "ros2"),
        default="foxglove",
        help="the recording's encoding: foxglove (default) or ros2 (ros2msg schemas, CDR: "
        "`ros2 bag play` reads it)",
    )


def record_parser(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    record = commands.add_parser("record", help="MCAP recordings: `pnav record info FILE`")
    verbs = record.add_subparsers(dest="record", metavar="VERB", required=True)
    info = verbs.add_parser("info", help="channels, schemas, messages, sim time, robots")
    info.add_argument("file", type=Path, help="an MCAP file (pnav up/demo --record)")
    info.add_argument("--json", metavar="FILE", help="also write it as JSON ('-': stdout only)")


def parse_counts(text: str, option: str) -> list[int]:
    """``"1,10,50"`` -> ``[1, 10, 50]``; UsageError naming ``option`` otherwise."""
    try:
        counts = [int(part) for part in text.split(",") if part.strip()]
    except ValueError:
        raise UsageError(f"{option} {text!r}: write whole numbers, e.g. 1,10,50") from None
    if not counts or min(counts) < 1:
        raise UsageError(f"{option} {text!r}: at least one count, each 1 or more")
    return counts


def robot_link_options(parser: argparse.ArgumentParser) -> None:
    """--robot-link and its ROS 2 settings (docs/ROS2.md), for `pnav up` and `pnav demo`."""
    parser.add_argument(
        "--robot-link",
        choices=("native", "ros2"),
        default="native",
        help="the wire between the robots and the bridge: native (default) or ros2 (the "
        "robots' topics on rmw_zenoh; the sim plays a ROS 2 robot)",
    )
    parser.add_argument(
        "--ros-domain-id", type=ros_domain, default=0, help="ROS_DOMAIN_ID (0 to 232, default 0)"
    )
    parser.add_argument(
        "--ros-router",
        metavar="ENDPOINT",
        default="",
        help="the rmw_zenoh router to join, e.g. tcp/localhost:7447 (default: the stack's own)",
    )
    parser.add_argument(
        "--ros-link-file", type=Path, help="per-robot namespaces and topic names (YAML)"
    )


def ros_domain(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if not 0 <= value <= 232:
        raise argparse.ArgumentTypeError(f"{value} is not within 0 to 232")
    return value


def robot_link_env(args: argparse.Namespace) -> dict[str, str]:
    """The variables common.robotlink reads, for the sim and the bridge."""
    real = getattr(args, "no_sim", False)  # `pnav up --no-sim`: real robots, no pybullet sim
    if args.robot_link == "native":
        if real:
            raise UsageError("--no-sim drives real robots: it needs --robot-link ros2")
        return {}
    env = {"PNAV_ROBOT_LINK": args.robot_link, "PNAV_ROS_DOMAIN_ID": str(args.ros_domain_id)}
    if args.ros_router:
        env["PNAV_ROS2_CONNECT"] = args.ros_router
    if args.ros_link_file is not None:
        if not args.ros_link_file.is_file():
            raise UsageError(f"--ros-link-file {args.ros_link_file}: no such file")
        # a bad file is refused now, not by each process
        link = load_link_file(args.ros_link_file)
        if real and link.clock != CLOCK_ROS:
            raise UsageError(
                f"--ros-link-file {args.ros_link_file}: with --no-sim no sim keeps the stack's "
                "clock; say clock: ros (docs/ROS2.md, The clock)"
            )
        if link.clock == CLOCK_ROS and not link.use_sim_time and not real:
            raise UsageError(
                f"--ros-link-file {args.ros_link_file}: the sim's stamps are sim time; with "
                "clock: ros it needs use_sim_time: true (docs/ROS2.md, The clock)"
            )
        env["PNAV_ROS2_LINK_FILE"] = str(args.ros_link_file.resolve())
    elif real:
        raise UsageError(
            "--no-sim needs a --ros-link-file with clock: ros (the robots' time, docs/ROS2.md)"
        )
    return env
