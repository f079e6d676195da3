"""The recorder (``python -m pnav.record FILE``) alone against the contract: a foreign client
writes a small mission's rows and notifications and plays the sim clock; the recorder is
stopped with SIGTERM; the MCAP is read back with the ``mcap`` reader.

Checked: it exits 0 and the file has its summary; every channel has messages; each topic has
the schema docs/RECORDING.md names; log times (and message timestamps) are sim time.
"""

from __future__ import annotations

import asyncio
import json
import math
import os
import re
import signal
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from mcap.decoder import DecoderFactory as McapDecoderFactory
from mcap.reader import make_reader
from mcap.records import Schema
from mcap_protobuf.decoder import DecoderFactory

from common.config import ZenohSettings
from common.contract import keys
from common.runtime import Runtime
from pnav._testing import ClockPlayer
from pnav.cli import program as cli
from pnav.record import topics

pytestmark = pytest.mark.timeout(90)

DOC = Path(__file__).resolve().parents[3] / "docs" / "RECORDING.md"
ROBOT = "r1"


async def start_recorder(
    path: Path, db_url: str, zenoh: ZenohSettings, encoding: str = "foxglove"
) -> Any:
    env = {
        **os.environ,
        "PNAV_DATABASE_URL": db_url,
        **zenoh.to_env(),
        "PNAV_INSTANCE": "recorder-1",
    }
    process = await asyncio.create_subprocess_exec(
        sys.executable,
        "-m",
        "pnav.record",
        str(path),
        "--encoding",
        encoding,
        env=env,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.STDOUT,
    )
    assert process.stdout is not None
    while True:  # subscribed once it says where it records
        line = (await asyncio.wait_for(process.stdout.readline(), 30)).decode()
        assert line, "the recorder exited before it started recording"
        if "recording to" in line:
            return process


async def write_mission(rt: Runtime) -> dict[str, list[float]]:
    """A small mission's rows, each notified after commit; the sim stamps written per table."""
    db = rt.database
    notify = db.notifier.notify
    stamps: dict[str, list[float]] = {}
    async with db.pool.acquire() as conn:
        await conn.execute("INSERT INTO robot (robot_id, world) VALUES ($1, 'test')", ROBOT)
        await conn.execute(
            "INSERT INTO map (map_id, resolution_m, origin_x, origin_y, width, height, grid) "
            "VALUES ('test', 0.5, -1.0, -2.0, 4, 3, $1)",
            bytes([0, 0, 100, 255] * 3),
        )
        await conn.execute(
            "INSERT INTO charging_station VALUES ('dock1', 'test', 0.5, 0.5, 0.3, 20.0)"
        )
        notify(keys.MAP, None, None)
        for i, stamp in enumerate((10.0, 10.1, 10.2)):
            row_id = await conn.fetchval(
                "INSERT INTO odometry (robot_id, stamp, seq, x, y, yaw, linear_mps, angular_rps)"
                " VALUES ($1, $2, $3, $4, 0.5, 0.3, 0.1, 0.0) RETURNING id",
                ROBOT,
                stamp,
                i,
                0.1 * i,
            )
            stamps.setdefault("odometry", []).append(stamp)
        notify(keys.ODOMETRY, ROBOT, row_id)  # one hint for the burst, as the bridge does
        scan = 0
        for stamp in (10.0, 10.2):
            scan = await conn.fetchval(
                "INSERT INTO laser_scan (robot_id, stamp, angle_min, angle_increment, range_min, "
                "range_max, ranges) VALUES ($1, $2, 0, $3, 0.12, 3.5, $4) RETURNING id",
                ROBOT,
                stamp,
                2 * math.pi / 360,
                [1.5] * 359 + [math.inf],
            )
            notify(keys.LASER_SCAN, ROBOT, scan)
            stamps.setdefault("laser_scan", []).append(stamp)
        await conn.execute(
            "INSERT INTO battery (robot_id, stamp, energy_wh, capacity_wh, percentage, charging, "
            "power_w) VALUES ($1, 10.0, 10.0, 19.98, 50.05, false, 1.5)",
            ROBOT,
        )
        notify(keys.BATTERY, ROBOT, None)
        await conn.execute(
            "INSERT INTO collision_event (robot_id, stamp, other, x, y) "
            "VALUES ($1, 10.15, 'pallet1', 0.2, 0.5)",
            ROBOT,
        )
        notify(keys.COLLISION_EVENT, ROBOT, None)
        goal = await conn.fetchval(
            "INSERT INTO goal (robot_id, x, y, stamp) VALUES ($1, 3.0, 1.0, 10.0) RETURNING id",
            ROBOT,
        )
        notify(keys.GOAL, ROBOT, goal)
        await conn.execute(
            "INSERT INTO planned_path (robot_id, stamp, goal_id, target, target_x, target_y, xs, "
            "ys, length_m) VALUES ($1, 10.05, $2, 'goal', 3.0, 1.0, '{0,1.5,3}', '{0.5,0.8,1}', "
            "3.1)",
            ROBOT,
            goal,
        )
        notify(keys.PLANNED_PATH, ROBOT, None)
        rec = await conn.fetchval(
            "INSERT INTO command_recommendation (robot_id, kind, source, priority, linear_mps, "
            "angular_rps, stamp, expires_stamp, inputs, reason) VALUES ($1, 'robot', "
            "'avoid_left', 50, 0.1, 0.5, 10.2, 10.7, $2::jsonb, 'obstacle ahead') RETURNING id",
            ROBOT,
            {"laser_scan": scan, "scan_stamp": 10.2},  # the pool encodes jsonb (common.db)
        )
        notify(keys.COMMAND_RECOMMENDATION, ROBOT, rec)
        await conn.execute(
            "INSERT INTO command2robot (robot_id, stamp, linear_mps, angular_rps, "
            "recommendation_id, source, considered_ids, reason) VALUES ($1, 10.21, 0.1, 0.5, $2, "
            "'avoid_left', ARRAY[$2]::bigint[], 'highest priority')",
            ROBOT,
            rec,
        )
        notify(keys.COMMAND2ROBOT, ROBOT, None)
        await conn.execute(
            "INSERT INTO active_strategy (robot_id, strategy_code, source, stamp) "
            "VALUES ($1, 'GOTO_AVOID', 'default', 10.0)",
            ROBOT,
        )
        notify(keys.ACTIVE_STRATEGY, ROBOT, None)
        await conn.execute(
            "UPDATE goal SET status = 'reached', finished_stamp = 10.25 WHERE id = $1", goal
        )
        notify(keys.GOAL, ROBOT, goal)
        second = await conn.fetchval(
            "INSERT INTO goal (robot_id, x, y, stamp) VALUES ($1, 1.0, 1.0, 10.25) RETURNING id",
            ROBOT,
        )
        notify(keys.GOAL, ROBOT, second)
        async with conn.transaction():  # as `pnav goal` replaces a goal: one notification
            await conn.execute(
                "UPDATE goal SET status = 'superseded', finished_stamp = 10.3 WHERE id = $1",
                second,
            )
            third = await conn.fetchval(
                "INSERT INTO goal (robot_id, x, y, stamp) VALUES ($1, 2.0, 2.0, 10.3) RETURNING id",
                ROBOT,
            )
        notify(keys.GOAL, ROBOT, third)
    stamps["all"] = [10.0, 10.3]
    return stamps


def documented_topics() -> dict[str, str]:
    """topic -> schema, from docs/RECORDING.md's table."""
    rows = re.findall(r"^\| `(/[^`]+)` \| `([^`]+)` \|", DOC.read_text(), re.M)
    return dict(rows)


class JsonDecoderFactory(McapDecoderFactory):
    """JSON messages (the ``pnav.*`` schemas) as Python values."""

    def decoder_for(
        self, message_encoding: str, schema: Schema | None
    ) -> Callable[[bytes], Any] | None:
        return json.loads if message_encoding == "json" else None


def read_back(path: Path) -> tuple[Any, list[tuple[Any, Any, Any, Any]]]:
    with path.open("rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory(), JsonDecoderFactory()])
        summary = reader.get_summary()
        decoded = list(reader.iter_decoded_messages())
    return summary, decoded


async def test_a_recorded_mission_reads_back_with_the_documented_schemas_in_sim_time(
    client: Runtime,
    clock: ClockPlayer,
    db_url: str,
    zenoh_settings: ZenohSettings,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    path = tmp_path / "run.mcap"
    recorder = await start_recorder(path, db_url, zenoh_settings)
    try:
        stamps = await write_mission(client)
    finally:
        recorder.send_signal(signal.SIGTERM)
        output = (await asyncio.wait_for(recorder.stdout.read(), 30)).decode()
        code = await recorder.wait()
    assert code == 0, output
    summary, decoded = read_back(path)
    assert summary is not None and summary.statistics is not None  # closed cleanly

    by_topic = {c.topic: c for c in summary.channels.values()}
    expected = {t.replace("{robot}", ROBOT): s for t, s in topics.TOPICS.items()}
    assert set(by_topic) == set(expected)
    assert documented_topics() == topics.TOPICS  # the doc names what the code writes
    for topic, channel in by_topic.items():
        schema = summary.schemas[channel.schema_id]
        assert schema.name == expected[topic], topic
        assert summary.statistics.channel_message_counts[channel.id] > 0, f"{topic} is empty"
        pnav_json = schema.name.startswith("pnav.")
        assert (schema.encoding, channel.message_encoding) == (
            ("jsonschema", "json") if pnav_json else ("protobuf", "protobuf")
        ), topic

    messages: dict[str, list[tuple[int, Any]]] = {}
    for _, channel, message, value in decoded:
        messages.setdefault(channel.topic, []).append((message.log_time, value))
    # every log time is sim time: within the mission's stamps (10.0 .. 10.3 s), not wall time
    low, high = stamps["all"]
    for topic, entries in messages.items():
        for log_time, _ in entries:
            assert low * 1e9 - 1 <= log_time <= high * 1e9 + 1, (topic, log_time)
    # all three odometry rows, though one notification named only the newest
    poses = messages[f"/{ROBOT}/pose"]
    assert [t for t, _ in poses] == [round(s * 1e9) for s in stamps["odometry"]]
    assert [round(p.pose.position.x, 6) for _, p in poses] == [0.0, 0.1, 0.2]
    scans = messages[f"/{ROBOT}/scan"]
    assert [t for t, _ in scans] == [round(s * 1e9) for s in stamps["laser_scan"]]
    first = scans[0][1]
    assert first.frame_id == f"{ROBOT}/base_link" and len(first.ranges) == 360
    assert (first.timestamp.seconds, first.timestamp.nanos) == (10, 0)
    grid = messages["/map"][0][1]
    assert (grid.column_count, grid.row_stride, len(grid.data)) == (4, 4, 12)
    assert grid.data[2] == 100 and messages["/map"][0][0] == 10_000_000_000  # clock: 10 s
    path_msg = messages[f"/{ROBOT}/path"][0][1]
    assert [round(p.position.x, 3) for p in path_msg.poses] == [0.0, 1.5, 3.0]
    recommendation = messages[f"/{ROBOT}/recommendations"][0][1]
    assert recommendation["source"] == "avoid_left" and recommendation["inputs"]["laser_scan"]
    decision = messages[f"/{ROBOT}/decisions"][0][1]
    assert "avoid_left" in decision.message and decision.timestamp.nanos == 210_000_000
    events = [e.message for _, e in messages[f"/{ROBOT}/events"]]
    assert any(e.startswith("goal") and "reached" in e for e in events), events
    assert any(e.startswith("goal") and "superseded" in e for e in events), events
    assert len(messages[f"/{ROBOT}/goal"]) == 3
    assert any("collision with pallet1" in e for e in events), events
    assert any("strategy GOTO_AVOID" in e for e in events), events

    assert cli.main(["record", "info", str(path)]) == 0
    text = capsys.readouterr().out
    assert "robots: r1" in text and "/r1/scan" in text and "foxglove.LaserScan" in text
    assert "sim time 10.00 to 10.30 s" in text


async def test_a_restarted_recorder_keeps_the_first_part(
    client: Runtime, db_url: str, zenoh_settings: ZenohSettings, tmp_path: Path
) -> None:
    path = tmp_path / "run.mcap"
    path.write_bytes(b"an earlier part")
    recorder = await start_recorder(path, db_url, zenoh_settings)
    recorder.send_signal(signal.SIGTERM)
    assert await asyncio.wait_for(recorder.wait(), 30) == 0
    assert path.read_bytes() == b"an earlier part"
    summary, _ = read_back(tmp_path / "run-2.mcap")
    assert summary is not None


def test_record_info_refuses_what_is_not_a_recording(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert cli.main(["record", "info", str(tmp_path / "none.mcap")]) == 2
    (tmp_path / "x.mcap").write_text("not mcap")
    assert cli.main(["record", "info", str(tmp_path / "x.mcap")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and "no recording at" in err[0] and "not a readable MCAP" in err[1]
