"""`pnav learn dataset` on a recorded run: `pnav bench nav --keep-db` keeps a real stack run's
database (GOTO_FAST: dwa drives), and the dataset exported from it matches the database:
one example per decision that has a scan, odometry and a path; sampled values equal what the
rows say. Relabelled (`--label dwa`, DAgger's step), its targets are dwa's choice for each
recorded state: for the decisions dwa won, what dwa decided then; for sampled rows, what
pnav_local.dwa.choose makes of the database's rows."""

from __future__ import annotations

import asyncio
import json
import math
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import asyncpg
import numpy as np
import pyarrow.parquet as pq
import pytest

from common.contract import records
from common.contract.planned_path import planned_path_of
from common.contract.records import LaserScan, Odometry
from pnav.run.embedded_postgres import EmbeddedPostgres
from pnav_learned.features import FEATURES, sector_minima
from pnav_local import dwa
from pnav_local.dwa_params import DwaParams

pytestmark = [pytest.mark.slow, pytest.mark.timeout(300)]

ROOT = Path(__file__).resolve().parents[2]


def pnav(*argv: str) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ)
    env.pop("PNAV_DATABASE_URL", None)
    return subprocess.run(
        [sys.executable, "-m", "pnav", *argv],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=240,
        check=False,
    )


async def rows(db_dir: Path) -> dict[str, list[asyncpg.Record]]:
    postgres = EmbeddedPostgres(db_dir)  # stopped at the end, the directory kept
    postgres.start()
    try:
        conn = await asyncpg.connect(postgres.dsn())
        try:
            return {
                "decisions": await conn.fetch(
                    "SELECT c.id, c.linear_mps, c.angular_rps, c.source, r.inputs"
                    " FROM command2robot c"
                    " LEFT JOIN command_recommendation r ON r.id = c.recommendation_id"
                ),
                "scans": await conn.fetch(
                    "SELECT id, angle_min, angle_increment, ranges FROM laser_scan"
                ),
                "odometry": await conn.fetch("SELECT id, linear_mps, angular_rps FROM odometry"),
                "collisions": await conn.fetch("SELECT id FROM collision_event"),
            }
        finally:
            await conn.close()
    finally:
        postgres.stop()


@pytest.fixture(scope="module")
def kept_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One short GOTO_FAST run's kept database (shared: a stack run is the slow part)."""
    keep = tmp_path_factory.mktemp("kept") / "dbs"
    done = pnav(
        *("bench", "nav", "--levels", "easy", "--worlds", "1"),
        *("--combos", "GOTO_FAST/turn_then_move", "--in-process", "--keep-db", str(keep)),
    )
    assert done.returncode == 0, done.stdout + done.stderr
    (db_dir,) = keep.iterdir()
    assert db_dir.name == "barn_easy_000__GOTO_FAST-turn_then_move__0"
    return db_dir


def test_the_dataset_of_a_kept_run_matches_its_database(kept_run: Path, tmp_path: Path) -> None:
    db_dir = kept_run
    out = tmp_path / "run.parquet"
    done = pnav("learn", "dataset", "--db-dir", str(db_dir), "--out", str(out))
    assert done.returncode == 0, done.stdout + done.stderr

    table = pq.read_table(out)
    assert json.loads(table.schema.metadata[b"pnav.features"]) == list(FEATURES)
    data = table.to_pydict()
    db = asyncio.run(rows(db_dir))
    decisions = {r["id"]: r for r in db["decisions"]}
    # every decision is an example or counted as skipped, and the run was mostly driving
    examples, total = len(data["decision_id"]), len(decisions)
    assert f"{examples} examples from {total} decisions" in done.stdout
    assert examples > 0.5 * total > 50
    assert set(data["decision_id"]) <= set(decisions)
    assert len(set(data["decision_id"])) == examples
    assert "dwa" in set(data["source"]) and set(data["strategy"]) == {
        "NAV_GOTO_FAST_TURN_THEN_MOVE"
    }
    assert not any(data["collision"]) and not db["collisions"]  # an easy world, no contact
    (status,) = set(data["goal_status"])  # one goal, as the database has it now
    assert status in ("active", "reached")

    scans = {r["id"]: r for r in db["scans"]}
    odom = {r["id"]: r for r in db["odometry"]}
    for i in np.linspace(0, examples - 1, 12).astype(int):
        decision = decisions[data["decision_id"][i]]
        assert data["linear_mps_cmd"][i] == decision["linear_mps"]
        assert data["angular_rps_cmd"][i] == decision["angular_rps"]
        assert data["source"][i] == decision["source"]
        inputs = json.loads(decision["inputs"]) if decision["inputs"] else {}
        if "laser_scan" in inputs:  # a controller's: the very scan it saw
            assert data["scan_id"][i] == inputs["laser_scan"]
        scan = scans[data["scan_id"][i]]
        sectors = sector_minima(scan["ranges"], scan["angle_min"], scan["angle_increment"])
        got = [data[f"sector_{k:02d}"][i] for k in range(16)]
        assert got == pytest.approx(sectors.tolist())
        o = odom[data["odometry_id"][i]]
        assert (data["linear_mps"][i], data["angular_rps"][i]) == (
            o["linear_mps"],
            o["angular_rps"],
        )
    # the robot got closer to its goal over most decisions' next 3 s
    progress = np.asarray(data["progress_m"], dtype=float)
    assert np.nanmean(progress) > 0.1


async def state_rows(db_dir: Path, scan: int, odom: int, path: int) -> dict[str, Any]:
    """The rows of one recorded state, the robot row and the active strategy's params."""
    postgres = EmbeddedPostgres(db_dir)
    postgres.start()
    try:
        conn = await asyncpg.connect(postgres.dsn())
        try:
            (robot,) = await records.robots(conn)
            return {
                "robot": robot,
                "params": await conn.fetchval(
                    "SELECT s.params FROM active_strategy a"
                    " JOIN strategy s ON s.code = a.strategy_code"
                ),
                "scan": await conn.fetchrow("SELECT * FROM laser_scan WHERE id = $1", scan),
                "odometry": await conn.fetchrow("SELECT * FROM odometry WHERE id = $1", odom),
                "path": await conn.fetchrow("SELECT * FROM planned_path WHERE id = $1", path),
            }
        finally:
            await conn.close()
    finally:
        postgres.stop()


def test_relabelled_targets_are_dwas_choice_for_each_recorded_state(
    kept_run: Path, tmp_path: Path
) -> None:
    out = tmp_path / "dwa.parquet"
    done = pnav("learn", "dataset", "--db-dir", str(kept_run), "--out", str(out), "--label", "dwa")
    assert done.returncode == 0, done.stdout + done.stderr
    assert "labelled by dwa" in done.stdout
    table = pq.read_table(out)
    assert table.schema.metadata[b"pnav.label"] == b"dwa"
    data = table.to_pydict()
    n = len(data["decision_id"])
    assert set(data["source"]) == {"dwa"}  # the targets' source is the label's
    # dwa drove this run: where it won, its choice again is what it decided then (the state
    # read back from the rows is the very state it saw, to the bit)
    won = [i for i in range(n) if data["decided_source"][i] == "dwa"]
    assert len(won) > 0.5 * n > 50
    for i in won:
        assert data["linear_mps_cmd"][i] == pytest.approx(data["decided_linear_mps"][i], abs=1e-9)
        assert data["angular_rps_cmd"][i] == pytest.approx(data["decided_angular_rps"][i], abs=1e-9)
    # and any sampled row's label is what dwa.choose makes of the database's rows
    for i in np.linspace(0, n - 1, 8).astype(int):
        rows = asyncio.run(
            state_rows(kept_run, data["scan_id"][i], data["odometry_id"][i], data["path_id"][i])
        )
        robot, s, o, p = rows["robot"], rows["scan"], rows["odometry"], rows["path"]
        choice = dwa.choose(
            LaserScan(
                s["id"], s["robot_id"], s["stamp"], s["angle_min"], s["angle_increment"],
                s["range_min"], s["range_max"], np.asarray(s["ranges"], dtype=np.float32),
            ),
            Odometry(
                o["id"], o["robot_id"], o["stamp"], o["x"], o["y"], o["yaw"],
                o["linear_mps"], o["angular_rps"],
            ),
            robot,
            planned_path_of(p),
            DwaParams.read(json.loads(rows["params"])),
            robot.footprint_polygon,
        )  # fmt: skip
        if choice is None:
            assert math.isnan(data["linear_mps_cmd"][i])
            continue
        expected = dwa.command_for(choice, planned_path_of(p))
        assert (data["linear_mps_cmd"][i], data["angular_rps_cmd"][i]) == pytest.approx(
            (expected.linear, expected.angular), abs=1e-9
        )
