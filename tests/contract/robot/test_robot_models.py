"""A world with a Jackal-class robot, through the real sim and bridge, read back with plain
SQL: the robot row is the documented model, the scans have its lidar's shape and rate, and
the robot speeds up no faster than its acceleration limit."""

from __future__ import annotations

import asyncio
import itertools
import math
from pathlib import Path

import asyncpg
import pytest

from common.robotmodel import load_model
from pnav._testing import eventually
from pnav.run.launcher import WORLDS, launched
from pnav.run.stack_options import StackOptions

pytestmark = pytest.mark.timeout(180)

JACKAL = load_model("jackal")
ODOMETRY = "SELECT stamp, x, linear_mps FROM odometry WHERE robot_id = $1 ORDER BY id"
NEWEST = "SELECT stamp FROM odometry WHERE robot_id = $1 ORDER BY id DESC LIMIT 1"
INSERT = (
    "INSERT INTO command2robot (robot_id, stamp, linear_mps, angular_rps, reason) "
    "VALUES ($1, $2, $3, 0.0, 'contract test')"
)


def jackal_world(folder: Path) -> Path:
    """The open room, with a Jackal (j1) and a Burger (b1) facing +x down the room."""
    path = folder / "jackal_room.yaml"
    path.write_text(
        "name: jackal_room\n"
        f"map: {WORLDS / 'maps' / 'open_room.yaml'}\n"
        "robots:\n"
        "  - {id: j1, x: 0.8, y: 1.5, yaw: 0.0, model: jackal}\n"
        "  - {id: b1, x: 0.8, y: 3.5, yaw: 0.0}\n"
    )
    return path


async def test_a_jackal_world_gives_the_documented_row_scans_and_acceleration(
    tmp_path: Path,
) -> None:
    options = StackOptions(
        world=str(jackal_world(tmp_path)), rate="1", zenoh_port=None, services=("sim", "bridge")
    )
    async with launched(options) as stack:
        conn = await asyncpg.connect(stack.local.database_url)
        try:
            await eventually(lambda: conn.fetchrow(NEWEST, "j1"), within=30, what="odometry")
            # the robot row: every model column, as models/jackal.yaml says
            want = JACKAL.robot_row()
            columns = ", ".join(want)
            row = dict(await conn.fetchrow(f"SELECT {columns} FROM robot WHERE robot_id = 'j1'"))
            # the true box, as pairs (approx takes no nesting)
            assert row.pop("footprint_polygon") == want.pop("footprint_polygon")
            assert row == pytest.approx(want)
            burger = await conn.fetchrow("SELECT model, lidar_beams FROM robot WHERE robot_id='b1'")
            assert tuple(burger) == ("turtlebot3_burger", 360)

            # the scans: 720 beams over 270 degrees, 0.1 to 30 m, 50 per sim second
            await asyncio.sleep(1.0)
            scans = await conn.fetch(
                "SELECT stamp, angle_min, angle_increment, range_min, range_max, ranges "
                "FROM laser_scan WHERE robot_id = 'j1' ORDER BY id"
            )
            assert len(scans) >= 10
            for scan in scans:
                assert len(scan["ranges"]) == 720
                assert scan["angle_min"] == pytest.approx(math.radians(-135.0), abs=1e-6)
                fov = scan["angle_increment"] * 719
                assert fov == pytest.approx(math.radians(270.0), abs=1e-6)
                assert (scan["range_min"], scan["range_max"]) == (0.1, 30.0)
            stamps = [s["stamp"] for s in scans]
            gaps = [b - a for a, b in itertools.pairwise(stamps)]
            assert min(gaps) == pytest.approx(0.02, abs=0.005)  # 50 Hz of sim time
            # the middle beams look down the room (+x): the far wall, beyond a Burger's 3.5 m
            assert 3.5 < min(scans[-1]["ranges"][355:365]) < 4.5

            # drive at 2 m/s: the speed ramps at 10 m/s^2, then holds
            start = (await conn.fetchrow(NEWEST, "j1"))["stamp"]
            while (now := (await conn.fetchrow(NEWEST, "j1"))["stamp"]) < start + 0.6:
                await conn.execute(INSERT, "j1", now, 2.0)
                await asyncio.sleep(0.05)
            odometry = [r for r in await conn.fetch(ODOMETRY, "j1") if r["stamp"] >= start]
        finally:
            await conn.close()
    speeds = [(r["stamp"], r["linear_mps"]) for r in odometry]
    ramp = [(t, v) for t, v in speeds if 0.0 < v < 2.0]
    assert len(ramp) >= 3, speeds  # 0.2 s of ramp at 30 Hz odometry
    for (t0, v0), (t1, v1) in itertools.pairwise(speeds):
        # never faster than the limit (one physics step of slack for the sampling)
        assert v1 - v0 <= JACKAL.max_linear_accel_mps2 * (t1 - t0) + 10.0 / 240 + 1e-6
    for (t0, v0), (t1, v1) in itertools.pairwise(ramp):
        # ...and at the limit while ramping
        assert (v1 - v0) / (t1 - t0) == pytest.approx(JACKAL.max_linear_accel_mps2, rel=0.3)
    assert max(v for _, v in speeds) == pytest.approx(2.0)
