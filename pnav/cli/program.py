"""``pnav``: the proactive-nav command line: its entry point and what each command does (the
parser is pnav/cli/parser.py)."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING

import uvloop

from common.errors import PnavError, UsageError
from pnav.cli.dashboard_options import dashboard_options
from pnav.cli.options import (
    apply_processes,
    parse_counts,
    robot_link_env,
)
from pnav.cli.parser import build_parser

if TYPE_CHECKING:
    from common.contract.people import Pose
    from common.runtime import Runtime


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    apply_processes(args)
    try:
        return dispatch(args)
    except UsageError as exc:
        print(f"pnav: {exc}", file=sys.stderr)
        return 2
    except PnavError as exc:
        print(f"pnav: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130


def dispatch(args: argparse.Namespace) -> int:
    from pnav.cli import stack_commands

    if args.command == "up":
        return _up(args)
    if args.command == "down":
        return stack_commands.down()
    if args.command == "env":
        return stack_commands.env(args.role)
    if args.command == "migrate":
        return uvloop.run(stack_commands.migrate(args.wait, roles=args.roles))
    if args.command == "secrets":
        return _secrets(args)
    if args.command == "status":
        return uvloop.run(stack_commands.status(args.once or not sys.stdout.isatty()))
    if args.command in ("goal", "strategy", "cancel"):
        return uvloop.run(_drive(args))

    if args.command == "demo":
        from pnav.run import demo

        record = launcher_record(args.record, args.encoding)
        link = robot_link_env(args)
        return demo.run(
            args.json, args.rate, record, dashboard_options(args), args.model, link, args.encoding
        )
    if args.command == "record":
        from pnav.record import info

        return info.run(args.file, args.json)
    if args.command == "bench":
        return _bench(args)
    if args.command in ("worlds", "zone", "learn"):
        return _verbs(args)
    raise AssertionError(f"unhandled command {args.command}")  # argparse enforces the choices


def _verbs(args: argparse.Namespace) -> int:
    """The commands whose verbs live in their own module (``pnav worlds``, ``pnav zone``,
    ``pnav learn``)."""
    if args.command == "zone":
        from pnav.cli.zone_command import run_zone

        return uvloop.run(run_zone(args))
    if args.command == "learn":
        from pnav.cli.learn_command import run_learn

        return run_learn(args)
    from pnav.bench.nav.worlds_cli import run_worlds

    return run_worlds(args)


def _secrets(args: argparse.Namespace) -> int:
    from pnav.run.credentials import generate

    env_file, users_file = generate(args.dir, force=args.force)
    print(f"wrote {env_file} and {users_file} (mode 600); docs/DEPLOY.md, Least privilege")
    return 0


def _up(args: argparse.Namespace) -> int:
    from pnav.run.launcher import lockstep_env, parse_replace, parse_replicas
    from pnav.run.stack_options import StackOptions
    from pnav.run.up import up

    options = StackOptions(
        world=args.world,
        rate=args.rate,
        gui=args.gui,
        robots=args.robots,
        battery=args.battery,
        model=args.model,
        data_dir=args.data_dir,
        zenoh_port=args.zenoh_port,
        log_dir=args.log_dir,
        echo=not args.quiet,
        replicas=parse_replicas(args.replicas),
        replace=parse_replace(args.replace),
        record=launcher_record(args.record, args.encoding),
        record_encoding=args.encoding,
        dashboard=dashboard_options(args),
    )
    if args.lockstep:
        if args.robot_link != "native":
            raise UsageError("--lockstep runs only on the native robot link")
        options.extra_env.update(lockstep_env(options))
    options.extra_env.update(robot_link_env(args))
    if args.no_sim:
        # the sim's process only tells the bridge the world: the robots publish the rest
        options.extra_env["PNAV_SIM_WORLD_ONLY"] = "1"
    return uvloop.run(up(options))


def launcher_record(path: Path | None, encoding: str = "foxglove") -> Path | None:
    """``--record FILE`` checked before the stack starts (None: not recording)."""
    from pnav.run.launcher import record_target

    if path is None and encoding != "foxglove":
        raise UsageError(f"--encoding {encoding}: the encoding of a recording; add --record FILE")
    return None if path is None else record_target(path)


def _bench(args: argparse.Namespace) -> int:
    if args.bench == "engine":
        from pnav.bench import engine_rate

        return engine_rate.run(args.json, args.seconds, args.notifications)
    if args.bench == "startup":
        from pnav.bench import startup

        return startup.run(args.json, args.runs)
    if args.bench == "latency":
        from pnav.bench import latency_report
        from pnav.run.launcher import parse_replicas

        return latency_report.run(
            parse_counts(args.robots, "--robots"),
            args.hz,
            args.seconds,
            parse_replicas(args.replicas),
            args.json,
            latency_report.parse_links(args.robot_link),
            with_floor=not args.no_floor,
            layouts=latency_report.parse_layouts(args.processes),
        )
    if args.bench == "nav":
        from pnav.bench.nav import runner

        return runner.run(args)
    if args.bench == "faults":
        from pnav.bench import faults

        return faults.run(args.json, args.only, args.world, f"{args.rate:g}")
    raise AssertionError(f"unhandled bench {args.bench}")  # argparse enforces the choices


def _goal_poses(args: argparse.Namespace) -> tuple[Pose, list[Pose]]:
    """The goal's pose and the route's waypoints the arguments give (headings in radians)."""
    from common.contract.people import Pose

    def rad(deg: float | None) -> float | None:
        return None if deg is None else math.radians(deg)

    yaw_tol = rad(args.yaw_tolerance)
    if args.through is None:
        if args.x is None or args.y is None:
            raise UsageError("pnav goal: give X Y, or a route with --through")
        return Pose(args.x, args.y, rad(args.yaw), yaw_tol, args.tolerance), []
    if args.x is not None or args.yaw is not None:
        raise UsageError("pnav goal: --through gives the goal's pose (its last); drop X Y / --yaw")
    *route, (x, y, yaw) = args.through
    stop = args.stop_at_waypoints
    waypoints = [Pose(wx, wy, rad(wyaw), yaw_tol if wyaw is not None else None, None, stop)
                 for wx, wy, wyaw in route]  # fmt: skip
    return Pose(x, y, rad(yaw), yaw_tol if yaw is not None else None, args.tolerance), waypoints


async def _set_goal(rt: Runtime, args: argparse.Namespace) -> int:
    from pnav.cli import stack_commands

    goal, waypoints = _goal_poses(args)
    (robot,) = await stack_commands.pick_robots(rt, args.robot, one=True)
    goal_id = await stack_commands.set_route(rt, robot, goal, waypoints)
    facing = "" if goal.yaw is None else f" facing {math.degrees(goal.yaw):g} deg"
    route = f" through {len(waypoints)} waypoint(s)" if waypoints else ""
    print(f"{robot}: goal {goal_id} set to ({goal.x}, {goal.y}){facing}{route}")
    return 0


async def _drive(args: argparse.Namespace) -> int:
    from pnav.cli import stack_commands

    rt = await stack_commands.open_runtime()
    try:
        # a row the database refuses (a CHECK, say) is the user's input: one line, exit 2
        with stack_commands.refusal_as_contract_error():
            if args.command == "goal":
                return await _set_goal(rt, args)
            if args.command == "cancel":
                for robot in await stack_commands.pick_robots(rt, args.robot, one=False):
                    cancelled = await stack_commands.cancel_goal(rt, robot)
                    print(
                        f"{robot}: " + (f"goal {cancelled} cancelled" if cancelled else "no goal")
                    )
                return 0
            return await _set_strategy(rt, args.code, args.robot)
    finally:
        await rt.close()


async def _set_strategy(rt: Runtime, code: str, robot_arg: str | None) -> int:
    from pnav.cli import stack_commands

    await stack_commands.check_strategy(rt, code)
    failed = 0
    for robot in await stack_commands.pick_robots(rt, robot_arg, one=False):
        verdict, reason = await stack_commands.send_user_command(rt, robot, "SET_STRATEGY", code)
        print(f"{robot}: {verdict}: {reason}")
        failed += verdict != "accepted"
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
