"""A decision's provenance: back from command2robot to the sensor rows it came from."""

from __future__ import annotations

import math

import httpx
import pytest

from common.runtime import Runtime
from tests.contract.dashboard.conftest import Fleet, Running

pytestmark = pytest.mark.timeout(90)


async def test_a_decision_leads_back_to_its_recommendations_and_their_sensor_rows(
    running: Running, fleet: Fleet, foreign: Runtime, http: httpx.AsyncClient
) -> None:
    await fleet.robot()
    odom = await fleet.odometry(1.0, 2.0, 0.5, stamp=4.0)
    scan = await fleet.scan([0.4, math.inf, 2.0], stamp=4.1)
    drive = await fleet.recommendation("turn_then_move", 10, 0.2, {"odometry": odom})
    avoid = await fleet.recommendation(
        "avoid_left", 50, 0.0, {"laser_scan": scan, "scan_stamp": 4.1, "laser_scan_x": "n/a"}
    )
    gone = await fleet.recommendation("safety_stop", 100, 0.0, {"laser_scan": 10**9})
    decided = await fleet.decision(avoid, [drive, avoid, gone], "avoid_left")
    await foreign.database.pool.execute(
        "UPDATE command2robot SET safety = 'limited to 0 m/s: test' WHERE id = $1", decided
    )

    response = await http.get(f"/api/decisions/{decided}")
    assert response.status_code == 200, response.text
    trace = response.json()
    assert trace["table"] == "command2robot"
    assert trace["decision"]["id"] == decided
    assert trace["decision"]["safety"] == "limited to 0 m/s: test"  # read from the table
    by_source = {r["source"]: r for r in trace["recommendations"]}
    assert [r["source"] for r in trace["recommendations"]] == [
        "safety_stop",
        "avoid_left",
        "turn_then_move",
    ]
    assert by_source["avoid_left"]["won"] and not by_source["turn_then_move"]["won"]
    (scan_row,) = by_source["avoid_left"]["rows"]
    assert (scan_row["table"], scan_row["id"]) == ("laser_scan", scan)
    # the scan's 3 ranges are summarised: the nearest hit explains the avoidance
    assert scan_row["row"]["beams"] == 3 and scan_row["row"]["nearest_m"] == 0.4
    assert scan_row["row"]["stamp"] == 4.1
    (odom_row,) = by_source["turn_then_move"]["rows"]
    assert (odom_row["row"]["x"], odom_row["row"]["y"]) == (1.0, 2.0)
    # a row the retention policy pruned is named, with why it is missing
    (pruned,) = by_source["safety_stop"]["rows"]
    assert pruned["row"] is None and "retention policy" in pruned["note"]


async def test_a_system_command_leads_back_to_the_battery_row(
    running: Running, fleet: Fleet, foreign: Runtime, http: httpx.AsyncClient
) -> None:
    await fleet.robot()
    pool = foreign.database.pool
    battery = await pool.fetchval(
        "INSERT INTO battery (robot_id, stamp, energy_wh, capacity_wh, percentage, charging, "
        "power_w) VALUES ('r1', 3, 0.1, 19.98, 0.5, false, 1.2) RETURNING id"
    )
    rec = await pool.fetchval(
        "INSERT INTO command_recommendation (robot_id, kind, source, priority, system_command, "
        "stamp, expires_stamp, inputs, reason) VALUES ('r1', 'system', 'battery_check', 60, "
        "'CMD_BATTSAVE', 3, 5, $1, 'battery low') RETURNING id",
        {"battery": battery, "battery_stamp": 3.0},
    )
    command = await pool.fetchval(
        "INSERT INTO system_command (robot_id, command, recommendation_id, considered_ids, "
        "reason, stamp) VALUES ('r1', 'CMD_BATTSAVE', $1, $2, 'only one', 3) RETURNING id",
        rec,
        [rec],
    )
    trace = (await http.get(f"/api/system-commands/{command}")).json()
    (weighed,) = trace["recommendations"]
    assert weighed["system_command"] == "CMD_BATTSAVE" and weighed["won"]
    (row,) = weighed["rows"]
    assert row["table"] == "battery" and row["row"]["percentage"] == 0.5
