"""``pnav``: the proactive-nav command line."""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, NoReturn, cast

import uvloop

from common.contract import limits
from common.errors import PnavError, UsageError
from pnav.dashboard_cli import add_dashboard_options, dashboard_options
from pnav.navbench.worlds_cli import add_worlds_parser

if TYPE_CHECKING:
    from common.runtime import Runtime


class _Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one line (what is wrong, and where help is), exit 2:
    the usage block argparse prints first buries the reason under every option."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: {message} (see `{self.prog} --help`)\n")


def _number(
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
            raise argparse.ArgumentTypeError(f"must be {meaning}, got {text!r}")
        return value

    return parse


_GOAL_M = limits.GOAL_MAX_ABS_M
_MAX_TOL_M = limits.GOAL_MAX_TOLERANCE_M
_coordinate = _number(
    f"a finite number of metres within +-{_GOAL_M:.0f}", lambda v: abs(v) <= _GOAL_M
)
_tolerance = _number(
    f"a finite number of metres in (0, {_MAX_TOL_M:.0f}]", lambda v: 0 < v <= _MAX_TOL_M
)
_positive = _number("a finite number above 0", lambda v: v > 0)
_not_negative = _number("a finite number, 0 or more", lambda v: v >= 0)
_percent = _number("a percentage from 0 to 100", lambda v: 0 <= v <= 100)
_count = _number("a whole number, 1 or more", lambda v: v >= 1, int)
_port = _number("a port number from 1 to 65535", lambda v: 1 <= v <= 65535, int)


def _strategy_code(text: str) -> str:
    """A strategy code as the strategy table spells them (upper case, ``[A-Z0-9_]+``)."""
    code = text.strip().upper()
    if not code or not all(c.isascii() and (c.isalnum() or c == "_") for c in code):
        raise argparse.ArgumentTypeError(
            f"must be a strategy code of letters, digits and _ (e.g. GOTO_AVOID), got {text!r}"
        )
    return code


def _robot_model(text: str) -> str:
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


def _model_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--model",
        type=_robot_model,
        metavar="NAME|FILE",
        help="robot model of every robot the world does not give one (models/*.yaml; "
        "default turtlebot3_burger)",
    )


def _stack_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--world", default="warehouse", help="world name or file (warehouse)")
    parser.add_argument(
        "--rate", default="1", help="sim seconds per wall second, or 'max' (default 1)"
    )
    parser.add_argument("--gui", action="store_true", help="open the pybullet window")
    parser.add_argument("--robots", type=_count, help="run exactly N robots")
    parser.add_argument("--battery", type=_percent, help="start charge of every robot, percent")
    _model_option(parser)


def _record_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--record",
        type=Path,
        metavar="FILE",
        help="record the mission into FILE as MCAP, Foxglove's schemas (docs/RECORDING.md)",
    )


def _record_parser(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    record = commands.add_parser("record", help="MCAP recordings: `pnav record info FILE`")
    verbs = record.add_subparsers(dest="record", metavar="VERB", required=True)
    info = verbs.add_parser("info", help="channels, schemas, messages, sim time, robots")
    info.add_argument("file", type=Path, help="an MCAP file (pnav up/demo --record)")
    info.add_argument("--json", metavar="FILE", help="also write it as JSON ('-': stdout only)")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="pnav", description="proactive-nav: rule-based robot navigation")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    up = commands.add_parser("up", help="run the whole stack until Ctrl-C")
    _stack_options(up)
    up.add_argument("--data-dir", type=Path, help="keep Postgres data here (default: fresh)")
    up.add_argument("--zenoh-port", type=_port, default=7447, help="router port (7447)")
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

    _record_option(up)

    goal = commands.add_parser("goal", help="send a robot to X Y (replaces its goal)")
    goal.add_argument("x", type=_coordinate, help=f"metres, within +-{_GOAL_M:.0f}")
    goal.add_argument("y", type=_coordinate, help=f"metres, within +-{_GOAL_M:.0f}")
    goal.add_argument("--robot", help="robot id (needed when there are several)")
    goal.add_argument(
        "--tolerance", type=_tolerance, help=f"metres, in (0, {_MAX_TOL_M:.0f}] (default 0.15)"
    )

    strategy = commands.add_parser("strategy", help="switch strategy (GOTO_AVOID, ...)")
    strategy.add_argument("code", type=_strategy_code)
    strategy.add_argument("--robot", help="robot id (default: every robot)")

    cancel = commands.add_parser("cancel", help="cancel the active goal")
    cancel.add_argument("--robot", help="robot id (default: every robot)")

    status = commands.add_parser("status", help="a live table per robot")
    status.add_argument("--once", action="store_true", help="print once and exit")

    commands.add_parser("down", help="stop the stack started by `pnav up`")

    migrate = commands.add_parser(
        "migrate", help="apply the contract to PNAV_DATABASE_URL (waits for the server)"
    )
    migrate.add_argument(
        "--wait", type=_not_negative, default=60.0, help="seconds to wait for Postgres"
    )

    demo = commands.add_parser("demo", help="the demo mission (see README)")
    demo.add_argument("--json", metavar="FILE", help="also write the summary as JSON")
    demo.add_argument("--rate", default=None, help="sim rate (default: the demo's own)")
    _record_option(demo)
    _record_parser(cast("argparse._SubParsersAction[argparse.ArgumentParser]", commands))
    add_dashboard_options(demo, None)
    _model_option(demo)

    bench = commands.add_parser("bench", help="benchmarks: print figures and JSON")
    benches = bench.add_subparsers(dest="bench", metavar="BENCH", required=True)
    engine = benches.add_parser("engine", help="engine rules/s and wake-up latency")
    engine.add_argument("--json", metavar="FILE", help="write the figures as JSON ('-': stdout)")
    engine.add_argument("--seconds", type=_positive, default=3.0, help="throughput run length")
    engine.add_argument(
        "--notifications", type=_count, default=1000, help="notifications for the latency run"
    )
    startup = benches.add_parser("startup", help="start-up time to first command, and memory")
    startup.add_argument("--json", metavar="FILE", help="write the figures as JSON ('-': stdout)")
    startup.add_argument("--runs", type=_count, default=3, help="how many start-ups to time")
    latency = benches.add_parser(
        "latency", help="sense-to-act latency by stage, CPU and memory per process"
    )
    latency.add_argument(
        "--robots",
        default="1,10,50",
        help="robot counts, one run each (comma-separated, default 1,10,50)",
    )
    latency.add_argument("--hz", type=_positive, default=20.0, help="lidar and odometry rate")
    latency.add_argument(
        "--seconds", type=_positive, default=30.0, help="sim seconds measured per run (default 30)"
    )
    latency.add_argument(
        "--replicas",
        action="append",
        metavar="N|SERVICE=N",
        help="replicas: N of every scenario service, or SERVICE=N (repeatable)",
    )
    latency.add_argument("--json", metavar="FILE", help="write the figures as JSON ('-': stdout)")
    nav = benches.add_parser(
        "nav",
        help="navigation: success, SPL and BARN score of every strategy/planner combo per world",
        description="Runs the whole stack (sim at --rate max, in lockstep with it) in every "
        "world of a suite with every shipped strategy/planner combination, one episode per "
        "world, combo and run. The whole shipped suite is 60 worlds x 4 combos = 240 "
        "episodes, about 42 min on 2 cores (times --runs, twice with --monolith): --levels "
        "and --worlds run a subset.",
    )
    nav.add_argument(
        "--suite", type=Path, default=Path("worlds/barn"), help="suite folder (worlds/barn)"
    )
    nav.add_argument("--runs", type=_count, default=1, help="runs per world and combo, seed = run")
    nav.add_argument(
        "--model",
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
    # _SubParsersAction is invariant in its parser class; ours only makes _Parser ones
    add_worlds_parser(cast("argparse._SubParsersAction[argparse.ArgumentParser]", commands))
    return parser


def parse_counts(text: str, option: str) -> list[int]:
    """``"1,10,50"`` -> ``[1, 10, 50]``; UsageError naming ``option`` otherwise."""
    try:
        counts = [int(part) for part in text.split(",") if part.strip()]
    except ValueError:
        raise UsageError(f"{option} {text!r}: write whole numbers, e.g. 1,10,50") from None
    if not counts or min(counts) < 1:
        raise UsageError(f"{option} {text!r}: at least one count, each 1 or more")
    return counts


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
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
    from pnav import commands

    if args.command == "up":
        return _up(args)
    if args.command == "down":
        return commands.down()
    if args.command == "migrate":
        return uvloop.run(commands.migrate(args.wait))
    if args.command == "status":
        return uvloop.run(commands.status(args.once or not sys.stdout.isatty()))
    if args.command in ("goal", "strategy", "cancel"):
        return uvloop.run(_drive(args))
    if args.command == "demo":
        from pnav import demo

        record = launcher_record(args.record)
        return demo.run(args.json, args.rate, record, dashboard_options(args), args.model)
    if args.command == "record":
        from pnav.record import info

        return info.run(args.file, args.json)
    if args.command == "bench":
        return _bench(args)
    if args.command == "worlds":
        from pnav.navbench.worlds_cli import run_worlds

        return run_worlds(args)
    raise AssertionError(f"unhandled command {args.command}")  # argparse enforces the choices


def _up(args: argparse.Namespace) -> int:
    from pnav.launcher import StackOptions, lockstep_env, parse_replace, parse_replicas
    from pnav.up import up

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
        record=launcher_record(args.record),
        dashboard=dashboard_options(args),
    )
    if args.lockstep:
        options.extra_env.update(lockstep_env(options))
    return uvloop.run(up(options))


def launcher_record(path: Path | None) -> Path | None:
    """``--record FILE`` checked before the stack starts (None: not recording)."""
    from pnav.launcher import record_target

    return None if path is None else record_target(path)


def _bench(args: argparse.Namespace) -> int:
    if args.bench == "engine":
        from pnav.bench import engine

        return engine.run(args.json, args.seconds, args.notifications)
    if args.bench == "startup":
        from pnav.bench import startup

        return startup.run(args.json, args.runs)
    if args.bench == "latency":
        from pnav.bench import latency_report
        from pnav.launcher import parse_replicas

        return latency_report.run(
            parse_counts(args.robots, "--robots"),
            args.hz,
            args.seconds,
            parse_replicas(args.replicas),
            args.json,
        )
    if args.bench == "nav":
        from pnav.navbench import runner

        return runner.run(args)
    raise AssertionError(f"unhandled bench {args.bench}")  # argparse enforces the choices


async def _drive(args: argparse.Namespace) -> int:
    from pnav import commands

    rt = await commands.open_runtime()
    try:
        # a row the database refuses (a CHECK, say) is the user's input: one line, exit 2
        with commands.refusal_as_contract_error():
            if args.command == "goal":
                (robot,) = await commands.pick_robots(rt, args.robot, one=True)
                goal_id = await commands.set_goal(rt, robot, args.x, args.y, args.tolerance)
                print(f"{robot}: goal {goal_id} set to ({args.x}, {args.y})")
                return 0
            if args.command == "cancel":
                for robot in await commands.pick_robots(rt, args.robot, one=False):
                    cancelled = await commands.cancel_goal(rt, robot)
                    print(
                        f"{robot}: " + (f"goal {cancelled} cancelled" if cancelled else "no goal")
                    )
                return 0
            return await _set_strategy(rt, args.code, args.robot)
    finally:
        await rt.close()


async def _set_strategy(rt: Runtime, code: str, robot_arg: str | None) -> int:
    from pnav import commands

    await commands.check_strategy(rt, code)
    failed = 0
    for robot in await commands.pick_robots(rt, robot_arg, one=False):
        verdict, reason = await commands.send_user_command(rt, robot, "SET_STRATEGY", code)
        print(f"{robot}: {verdict}: {reason}")
        failed += verdict != "accepted"
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
