"""``python -m services.sim``: the simulator service.

    python -m services.sim --world worlds/warehouse.yaml [--gui] [--rate R|max] [--robots N]

Its benchmark (``python -m pnav.bench.sim_rate``) takes the same options.

Options fall back to environment variables (for containers): PNAV_SIM_WORLD, PNAV_SIM_RATE,
PNAV_SIM_ROBOTS, PNAV_SIM_BATTERY, PNAV_SIM_SEED, PNAV_SIM_SCAN_HZ, PNAV_SIM_MODEL,
PNAV_SIM_ODOM_HZ, PNAV_SIM_TRACE, PNAV_SIM_MAX_LAG, PNAV_SIM_CMD_TIMEOUT, PNAV_LOCKSTEP,
PNAV_SIM_HELD; Zenoh
comes from the PNAV_ZENOH_* variables (common.config.ZenohSettings). SIGINT and SIGTERM stop
it cleanly.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import sys
import threading
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from common.bus import open_session
from common.config import ZenohSettings, default_instance, env_number, lockstep_from_env
from common.contract import keys
from common.errors import ConfigError, ConnectionFailure, UsageError
from common.lifeline import die_with_parent
from common.log import event, setup
from common.robotlink import NATIVE, RobotLinkSettings
from services.sim.pacing import parse_rate
from services.sim.signals import SignalStop
from services.sim.sim import CMD_TIMEOUT_S, SimConfig
from services.sim.world_spec import World, load_world

log = logging.getLogger("services.sim")


def _env(name: str) -> str | None:
    value = os.environ.get(name, "").strip()
    return value or None


@dataclass(frozen=True)
class EnvOption:
    """An option that falls back to an environment variable (for containers): its help ends
    ``[ENV]``, or ``[ENV, default ...]`` when ``shown`` (or ``default``) says what is used
    with neither."""

    flag: str
    env: str
    help: str
    kind: type[int] | type[float] | None = None  # None: a string
    default: str | int | float | None = None
    shown: str | None = None
    metavar: str | None = None

    def add_to(self, ap: argparse.ArgumentParser) -> None:
        raw: str | int | float | None
        if self.kind is None:
            raw = _env(self.env)
        else:
            what = "a whole number" if self.kind is int else "a number"
            raw = env_number(os.environ, self.env, None, self.kind, what=what)
        shown = self.shown if self.shown is not None else self.default
        tail = f"[{self.env}]" if shown is None else f"[{self.env}, default {shown}]"
        ap.add_argument(
            self.flag,
            type=self.kind or str,
            default=self.default if raw is None else raw,
            metavar=self.metavar,
            help=f"{self.help} {tail}",
        )


SIM_OPTIONS = (
    EnvOption("--world", "PNAV_SIM_WORLD", "world file (or bare map_server YAML)"),
    EnvOption("--rate", "PNAV_SIM_RATE", "sim seconds per wall second, or 'max'", default="1"),
    EnvOption(
        "--robots",
        "PNAV_SIM_ROBOTS",
        "run exactly N robots: the world's first N, then extra ones placed on free spots",
        int,
    ),
    EnvOption(
        "--battery",
        "PNAV_SIM_BATTERY",
        "start charge of every robot, percent (overrides the world)",
        float,
    ),
    EnvOption("--seed", "PNAV_SIM_SEED", "seed of the sensor noise", int, default=0),
    EnvOption(
        "--scan-hz",
        "PNAV_SIM_SCAN_HZ",
        "every robot's lidar rate in sim time",
        float,
        shown="each robot model's lidar rate_hz",
    ),
    EnvOption(
        "--model",
        "PNAV_SIM_MODEL",
        "robot model of every robot the world does not give one: a name in models/ or a model file",
        shown="turtlebot3_burger",
    ),
    EnvOption(
        "--odom-hz", "PNAV_SIM_ODOM_HZ", "odometry rate in sim time", float, 30.0, shown="30"
    ),
    EnvOption(
        "--cmd-timeout",
        "PNAV_SIM_CMD_TIMEOUT",
        "stop a robot's wheels when no cmd_vel came for it for S sim seconds, as robot "
        "firmware does; 0: never",
        float,
        shown=f"{CMD_TIMEOUT_S:g}",
        metavar="S",
    ),
    EnvOption(
        "--max-lag",
        "PNAV_SIM_MAX_LAG",
        "pace by the stack: never run more than S sim seconds past a robot's newest "
        "decision (services/sim/lag_gate.py; for --rate max)",
        float,
    ),
    EnvOption(
        "--lockstep",
        "PNAV_LOCKSTEP",
        "step only when the stack is quiet: hold at 0 until these services (a comma list, "
        "e.g. bridge,strategy,planner,controller,decision) report, then wait after every "
        "message (services/sim/lockstep_barrier.py; same world and seed, same run)",
        metavar="SERVICES",
    ),
    EnvOption(
        "--trace",
        "PNAV_SIM_TRACE",
        "write when each sensor message left and each command arrived, for `pnav bench "
        "latency` (common/trace.py)",
    ),
)


def sim_parser(prog: str = "python -m services.sim") -> argparse.ArgumentParser:
    """The sim's options (its benchmark, pnav.bench.sim_rate, adds its own to them)."""
    ap = argparse.ArgumentParser(prog=prog, description="proactive-nav pybullet simulator")
    SIM_OPTIONS[0].add_to(ap)
    ap.add_argument("--gui", action="store_true", help="open the pybullet GUI (default headless)")
    for option in SIM_OPTIONS[1:]:
        option.add_to(ap)
    ap.add_argument(
        "--world-only",
        action="store_true",
        default=_env("PNAV_SIM_WORLD_ONLY") in ("1", "true", "yes", "on"),
        help="a real robot: only announce the world (its robots, map and stations) on "
        "pnav/sim/world; no physics, sensors, clock or cmd_vel (services/sim/announcer.py) "
        "[PNAV_SIM_WORLD_ONLY]",
    )
    ap.add_argument(
        "--held",
        action="store_true",
        default=_env("PNAV_SIM_HELD") in ("1", "true", "yes", "on"),
        help="hold at sim time 0, then run only as far as pnav/sim/run messages let it: "
        "{until: S} to sim time S, {until: nil} on (services/sim/hold.py) [PNAV_SIM_HELD]",
    )
    ap.add_argument(
        "--physics-hz", type=float, default=240.0, help="physics steps per sim second (default 240)"
    )
    return ap


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    return sim_parser().parse_args(argv)


def build(args: argparse.Namespace) -> tuple[World, SimConfig, float]:
    """The world, config and rate the arguments ask for; UsageError if they are wrong."""
    path = args.world
    if not path:
        raise ConfigError("no world: pass --world worlds/<name>.yaml or set PNAV_SIM_WORLD")
    world = load_world(path, args.model)
    if args.robots is not None:
        world = world.with_robot_count(args.robots)
    if args.battery is not None and not 0.0 <= args.battery <= 100.0:
        raise ConfigError(f"--battery {args.battery} must be a percentage within [0, 100]")
    if (
        args.gui
        and sys.platform.startswith("linux")
        and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
    ):
        # pybullet's GUI would call exit(1) from C with no display; say why instead
        raise ConfigError("--gui needs a display (DISPLAY is not set); run headless without it")
    if args.max_lag is not None and not args.max_lag > 0:
        raise ConfigError(f"--max-lag {args.max_lag} must be a positive number of sim seconds")
    args.lockstep = lockstep_from_env({"PNAV_LOCKSTEP": args.lockstep or ""})
    if args.lockstep and args.max_lag is not None:
        raise ConfigError("--lockstep and --max-lag exclude each other (lockstep always waits)")
    if args.lockstep and args.held:
        raise ConfigError("--lockstep and --held exclude each other (lockstep holds at 0 itself)")
    scan_ok = args.scan_hz is None or args.scan_hz > 0
    if not args.physics_hz > 0 or not scan_ok or not args.odom_hz > 0:
        raise ConfigError("--physics-hz, --scan-hz and --odom-hz must be positive")
    config = SimConfig(
        cmd_timeout_s=CMD_TIMEOUT_S if args.cmd_timeout is None else args.cmd_timeout,
        physics_hz=args.physics_hz,
        scan_hz=args.scan_hz,
        odom_hz=args.odom_hz,
        battery_percent=args.battery,
        seed=args.seed,
        gui=args.gui,
    )
    return world, config, parse_rate(args.rate)


def serve(
    world: World,
    config: SimConfig,
    rate: float,
    trace: str | None = None,
    max_lag: float | None = None,
    lockstep: tuple[str, ...] = (),
    held: bool = False,
) -> int:
    from common.trace import Tracer
    from services.sim.lag_gate import Gate
    from services.sim.node import SimNode

    stop = threading.Event()
    signals = SignalStop(stop)  # SIGINT and SIGTERM set ``stop`` (signals.py says how)
    link = RobotLinkSettings.from_env()
    ros2_session = None
    try:
        own = ZenohSettings.from_env()
        session = open_session(own)
        if link.link != NATIVE and link.connect:  # an rmw_zenoh router of its own
            ros2_session = open_session(link.session_settings(own))
        try:
            instance = _env("PNAV_INSTANCE") or default_instance()
            tracer = Tracer(Path(trace)) if trace else None
            gate = Gate(max_lag) if max_lag is not None else None
            node = SimNode(
                world,
                config,
                session,
                rate=rate,
                instance=instance,
                tracer=tracer,
                gate=gate,
                lockstep=lockstep,
                robot_link=link,
                ros2_session=ros2_session,
                held=held,
            )
            try:
                node.run(stop)
            finally:
                node.close()
        finally:
            if ros2_session is not None:
                ros2_session.close()
            session.close()
    finally:
        signals.close()  # stopped in time: no stack dump
    return 0


def announce_world(world: World) -> int:
    """``--world-only``: the world for a real robot's bridge, until SIGINT/SIGTERM."""
    from services.sim.announcer import announce
    from services.sim.node import SERVICE, WORLD_PERIOD_S

    stop = threading.Event()
    signals = SignalStop(stop)
    try:
        session = open_session(ZenohSettings.from_env())
        try:
            instance = _env("PNAV_INSTANCE") or default_instance()
            announce(world, session, stop, keys.alive_key(SERVICE, instance), WORLD_PERIOD_S)
        finally:
            session.close()
    finally:
        signals.close()
    return 0


def prestart(args: list[str]) -> None:
    """What the sim imports only once it runs (pnav.run.prestart imports it ahead, while the
    launcher makes Postgres ready): the node and its gate and tracer (:func:`serve`) and
    numpy's random module (the world's noise, numpy imports it on first use)."""
    for module in ("numpy.random", "common.trace", "services.sim.lag_gate", "services.sim.node"):
        importlib.import_module(module)


def main(argv: Sequence[str] | None = None) -> int:
    die_with_parent()
    setup("sim")
    try:
        args = parse_args(argv)
        world, config, rate = build(args)
        if args.world_only:
            return announce_world(world)
        return serve(world, config, rate, args.trace, args.max_lag, args.lockstep, args.held)
    except UsageError as exc:
        event(log, logging.ERROR, "cannot start the sim", problem=str(exc))
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except ConnectionFailure as exc:
        event(log, logging.ERROR, "cannot reach Zenoh", problem=str(exc))
        return 1


if __name__ == "__main__":
    sys.exit(main())
