"""The simulation proper: fixed physics steps, robots, batteries and sensors on sim time.

:class:`Simulation` knows nothing of Zenoh or wall time. Each :meth:`Simulation.step` first
takes the sensor readings due at the current sim time (through ``sink``), then advances the
world by one physics step. The node (node.py) paces steps against the wall clock and turns
sink calls into Zenoh publications; the benchmark (bench.py) runs steps flat out.
"""

from __future__ import annotations

import logging
import math
import threading
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

import services.sim.messages as messages
from common.contract import keys
from common.errors import ConfigError
from common.log import event
from common.robotmodel import RobotModel
from services.sim.battery import Battery, BatteryModel
from services.sim.fleetcast import Cast, FleetCast
from services.sim.lidar import Lidar
from services.sim.movers import Movers
from services.sim.outline import Outline
from services.sim.pacing import Every
from services.sim.physics import CONTACT_TOLERANCE_M, Scene
from services.sim.robot import RobotState, accelerate, clamp_command, integrate
from services.sim.world_spec import World

log = logging.getLogger(__name__)

# Robot firmware stops the wheels when its command stream goes quiet for this long (the
# TurtleBot3's OpenCR firmware and ROS's diff_drive_controller both use 0.5 s): the bridge's
# watchdog cannot stop a robot when what is down is the network between them.
CMD_TIMEOUT_S = 0.5

# (robot_id, topic, message): topic is one of common.contract.keys.SENSOR_TOPICS
Sink = Callable[[str, str, dict[str, Any]], None]

# the sensor topics, as the contract names them
SCAN, ODOM, BATTERY, COLLISION = keys.SCAN, keys.ODOM, keys.BATTERY_MSG, keys.COLLISION


@dataclass(frozen=True)
class SimConfig:
    physics_hz: float = 240.0
    # every robot's lidar rate; None: each robot's model's (common/robotmodel.py)
    scan_hz: float | None = None
    odom_hz: float = 30.0
    battery_hz: float = 1.0
    battery: BatteryModel = field(default_factory=BatteryModel)
    battery_percent: float | None = None  # start charge of every robot; None: the world's
    seed: int = 0
    gui: bool = False
    # stop a robot's wheels when no command came for this many sim seconds; 0: never
    cmd_timeout_s: float = CMD_TIMEOUT_S

    def __post_init__(self) -> None:
        # NaN fails both tests; inf is refused too: 0 is how to say "never"
        if not 0.0 <= self.cmd_timeout_s < math.inf:
            raise ConfigError(
                f"cmd timeout {self.cmd_timeout_s} (--cmd-timeout, PNAV_SIM_CMD_TIMEOUT) must "
                "be a number of sim seconds >= 0 (0: never time out)"
            )


class Simulation:
    def __init__(self, world: World, config: SimConfig, sink: Sink) -> None:
        self.world = world
        self.config = config
        self.sink = sink
        self.dt = 1.0 / config.physics_hz
        self.steps = 0
        self.rng = np.random.default_rng(config.seed)
        self.robots = [RobotState(r.robot_id, r.x, r.y, r.yaw, r.model) for r in world.robots]
        self.index = {r.robot_id: i for i, r in enumerate(self.robots)}
        self.batteries = [
            Battery.at_percent(
                replace(config.battery, capacity_wh=r.model.battery_capacity_wh),
                _start_percent(config.battery_percent, r.battery_percent),
            )
            for r in world.robots
        ]
        # robot i's lidar, one object per distinct lidar model
        shared: dict[object, Lidar] = {}
        self.lidars = [shared.setdefault(r.model.lidar, Lidar(r.model.lidar)) for r in world.robots]
        self.scene = Scene(world, gui=config.gui)
        # every robot's lidar, in closed form (Bullet only moves bodies and finds contacts)
        self.cast = FleetCast(Outline.of(world), world.models, self.lidars)
        # the moving obstacles, where they are at sim time 0 (services/sim/movers.py)
        self.movers = Movers(world.movers, self.scene)
        self._touching: list[frozenset[str]] = [frozenset() for _ in self.robots]
        self._seq: dict[tuple[int, str], int] = {}
        # Each robot's sensors run on its own phase, i/N of a period after robot 0's, as the
        # clocks of independent robots would: in phase, a fleet's readings would all land in
        # the same instant and every service would see them as one burst.
        n = len(self.robots)
        self._schedule = [
            {
                SCAN: Every(1.0 / (config.scan_hz or spec.model.lidar.rate_hz), self.dt, i / n),
                ODOM: Every(1.0 / config.odom_hz, self.dt, i / n),
                BATTERY: Every(1.0 / config.battery_hz, self.dt, i / n),
            }
            for i, spec in enumerate(world.robots)
        ]
        # commands arrive on Zenoh's threads; the loop takes them under this lock
        self._lock = threading.Lock()
        self._pending: dict[int, tuple[float, float]] = {}
        # the step each robot's newest command was taken at, None once it timed out (or
        # before the first): counted in whole steps, so the timeout is exact in sim time
        self._commanded_at: list[int | None] = [None for _ in self.robots]
        self._timeout_steps = (
            math.ceil(config.cmd_timeout_s / self.dt - 1e-9) if config.cmd_timeout_s > 0 else 0
        )
        self.cmd_timeout_stops = 0  # robots whose wheels the timeout stopped
        # metres each robot moved since it last took a command, and the most any did: how
        # far a robot goes on a command stream that stopped (pnav bench faults)
        self._after_command_m = [0.0 for _ in self.robots]
        self.max_after_command_m = 0.0
        self.counts: dict[str, int] = {SCAN: 0, ODOM: 0, BATTERY: 0, COLLISION: 0}
        # contact tests skipped per robot while its clearance lasts; the closing speed bound
        # is two robots driving at each other flat out (a polygon's corners swinging round at
        # its top turn rate on top: a disc's outline does not move as it turns), or a robot
        # and the fastest mover
        self._unchecked = [0 for _ in self.robots]
        top = max(_outline_speed(r.model) for r in self.robots)
        self._closing = (top + max(top, self.movers.top_speed_mps)) * self.dt
        for i, r in enumerate(self.robots):
            self._touching[i] = self.scene.probe(i, r.x, r.y)[0]

    @property
    def time(self) -> float:
        """Sim time, s: whole steps times the step, so it never drifts."""
        return self.steps * self.dt

    def set_command(self, robot_id: str, linear: float, angular: float) -> bool:
        """Obey (linear, angular) from the next step on, until another command or for
        ``cmd_timeout_s`` of sim time at most; thread-safe. False if there is no such robot."""
        i = self.index.get(robot_id)
        if i is None:
            return False
        with self._lock:
            self._pending[i] = (linear, angular)
        return True

    def step(self) -> None:
        """Sense what is due now, then advance the world by one physics step."""
        self._sense()
        if self._pending:
            with self._lock:
                pending, self._pending = self._pending, {}
            for i, (v, w) in pending.items():
                self.robots[i].cmd_linear, self.robots[i].cmd_angular = v, w
                self._commanded_at[i] = self.steps
                self._after_command_m[i] = 0.0
        if self._timeout_steps:
            self._time_out_commands()
        self.steps += 1
        if self.movers:
            self.movers.place(self.time)  # before the robots: their contact tests meet them
        for i, robot in enumerate(self.robots):
            self._advance(i, robot)

    def run_for(self, sim_seconds: float) -> None:
        for _ in range(round(sim_seconds / self.dt)):
            self.step()

    def close(self) -> None:
        self.scene.close()

    # -- internals -------------------------------------------------------------------------
    def _time_out_commands(self) -> None:
        """Stop the wheels of every robot whose newest command is cmd_timeout_s old: it has
        then been obeyed for exactly that long."""
        for i, since in enumerate(self._commanded_at):
            if since is None or self.steps - since < self._timeout_steps:
                continue
            self._commanded_at[i] = None
            robot = self.robots[i]
            if robot.cmd_linear == 0.0 and robot.cmd_angular == 0.0:
                continue  # already standing: nothing to stop, nothing to count
            robot.cmd_linear = robot.cmd_angular = 0.0
            self.cmd_timeout_stops += 1
            event(
                log,
                logging.WARNING,
                "no cmd_vel: wheels stopped",
                robot=robot.robot_id,
                sim_time=round(self.time, 3),
                timeout_s=self.config.cmd_timeout_s,
            )

    def _drive(self, robot: RobotState, empty: bool) -> tuple[float, float]:
        """The motors' velocities this step: the clamped command, reached no faster than the
        model's acceleration limits (a flat battery brakes them the same way)."""
        m = robot.model
        v, w = (0.0, 0.0) if empty else clamp_command(m, robot.cmd_linear, robot.cmd_angular)
        robot.drive_linear = accelerate(robot.drive_linear, v, m.max_linear_accel_mps2, self.dt)
        robot.drive_angular = accelerate(robot.drive_angular, w, m.max_angular_accel_rps2, self.dt)
        return robot.drive_linear, robot.drive_angular

    def _advance(self, i: int, robot: RobotState) -> None:
        x0, y0 = robot.x, robot.y
        self._move(i, robot)
        if robot.x != x0 or robot.y != y0:
            self._after_command_m[i] += math.hypot(robot.x - x0, robot.y - y0)
            self.max_after_command_m = max(self.max_after_command_m, self._after_command_m[i])

    def _move(self, i: int, robot: RobotState) -> None:
        bat = self.batteries[i]
        v, w = self._drive(robot, bat.empty)
        if self._unchecked[i] > 0:
            # nothing was near enough to be reached by now: move without the contact test
            self._unchecked[i] -= 1
            if v != 0.0 or w != 0.0:
                robot.x, robot.y, robot.yaw = integrate(robot.x, robot.y, robot.yaw, v, w, self.dt)
                self.scene.place(i, robot.x, robot.y, robot.yaw)
            robot.linear, robot.angular = v, w
            touching: frozenset[str] = frozenset()
        else:
            if v == 0.0 and w == 0.0:
                robot.linear = robot.angular = 0.0
                touching, clearance = self.scene.probe(i, robot.x, robot.y)
            else:
                old = (robot.x, robot.y, robot.yaw)
                moved = self.scene.move(i, old, integrate(*old, v, w, self.dt))
                robot.x, robot.y, robot.yaw = moved.x, moved.y, moved.yaw
                # a polygon whose turn was blocked kept its heading: it did not turn
                turned = moved.yaw != old[2]
                robot.linear, robot.angular = v * moved.fraction, w if turned else 0.0
                touching, clearance = moved.touching, moved.clearance
            # this robot and any other close in by at most _closing per step, and the walls
            # not at all (a box mover's corner may jump by turn_jump_m where its path turns):
            # until the clearance is used up, the test cannot find anything
            room = clearance - CONTACT_TOLERANCE_M - self.movers.turn_jump_m
            self._unchecked[i] = max(0, int(room / self._closing) - 1)
        bat.step(self.dt, robot.linear, robot.angular, self._charge_power(robot))
        for other in sorted(touching - self._touching[i]):
            msg = messages.collision(
                self.time, self._next_seq(i, COLLISION), other, robot.x, robot.y
            )
            self._emit(i, COLLISION, msg)
        self._touching[i] = touching

    def _charge_power(self, robot: RobotState) -> float | None:
        best: float | None = None
        for st in self.world.stations:
            if math.hypot(robot.x - st.x, robot.y - st.y) <= st.radius_m:
                best = st.charge_power_w if best is None else max(best, st.charge_power_w)
        return best

    def _sense(self) -> None:
        now, step = self.time, self.steps
        # every robot that scans now, cast together (docs/ARCHITECTURE.md, batching across robots)
        scanning = [i for i, due in enumerate(self._schedule) if due[SCAN].due(step)]
        casts: dict[int, Cast] = {}
        if scanning:
            poses = [(r.x, r.y, r.yaw) for r in self.robots]
            casts = dict(zip(scanning, self.cast(poses, scanning), strict=True))
            if self.movers:
                casts = {i: self.movers.cast(c, poses[i], self.lidars[i]) for i, c in casts.items()}
        for i, robot in enumerate(self.robots):
            due = self._schedule[i]
            if due[ODOM].due(step):
                self._emit(i, ODOM, messages.odom(now, self._next_seq(i, ODOM), robot))
            if i in casts:
                # in robot order, as before batching: the noise stream is drawn in that order
                lidar = self.lidars[i]
                ranges = lidar.ranges(*casts[i], self.rng)
                msg = messages.scan(now, self._next_seq(i, SCAN), lidar.params, ranges)
                self._emit(i, SCAN, msg)
            if due[BATTERY].due(step):
                bat = self.batteries[i]
                self._emit(i, BATTERY, messages.battery(now, self._next_seq(i, BATTERY), bat))

    def _next_seq(self, i: int, topic: str) -> int:
        seq = self._seq.get((i, topic), 0)
        self._seq[(i, topic)] = seq + 1
        return seq

    def _emit(self, i: int, topic: str, message: dict[str, Any]) -> None:
        self.counts[topic] += 1
        self.sink(self.robots[i].robot_id, topic, message)


def _start_percent(override: float | None, from_world: float | None) -> float:
    if override is not None:
        return override
    return 100.0 if from_world is None else from_world


def _outline_speed(model: RobotModel) -> float:
    """The fastest any point of a robot's outline moves, m/s."""
    fp = model.footprint
    return model.max_linear_mps + (
        0.0 if fp.is_disc else model.max_angular_rps * fp.circumscribed_m
    )
