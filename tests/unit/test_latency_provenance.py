"""Sense-to-act samples joined from provenance: what counts, from where, and the stages."""

from __future__ import annotations

from pathlib import Path

import pytest

from common.trace import CMD_VEL, NO_REF, TraceEvent, Tracer, read_trace
from pnav.bench import provenance_samples as prov
from pnav.bench.hall import write_hall
from pnav.bench.latency_report import (
    beside_floor,
    latency_figures,
    parse_layouts,
    parse_links,
    separation_price,
    table,
    target_for,
)
from pnav.bench.sense_to_act import join_trace, notifications_lost
from services.sim.world_spec import load_world

T0 = 1_800_000_000.0  # wall seconds, as Postgres' clock_timestamp() gives them
US = 1e-3  # ms: float seconds near T0 resolve about 0.24 us, Postgres stamps 1 us


def command(
    cid: int, rec: int, inputs: dict[str, object], decided: float = T0 + 0.004
) -> prov.Command:
    return prov.Command(cid, "r1", rec, decided, "planner", T0 + 0.003, inputs)


ROWS = {
    ("odometry", 7): prov.SensorRow("odometry", 7, "r1", 70, T0 + 0.001),
    ("laser_scan", 9): prov.SensorRow("laser_scan", 9, "r1", 90, T0 + 0.0015),
}
PUBLISHED = {("odom", "r1", 70): T0, ("scan", "r1", 90): T0 + 0.0005}


def test_a_sample_runs_from_the_sensor_message_to_the_command_at_the_sim() -> None:
    arrivals = {100: T0 + 0.005}
    (sample,), missing = prov.samples(arrivals, [command(100, 1, {"odometry": 7})], ROWS, PUBLISHED)
    assert sample.total_ms == pytest.approx(5.0, abs=US)
    assert sample.stages_ms() == pytest.approx(
        {
            "sensor_to_row": 1.0,
            "row_to_recommendation": 2.0,
            "recommendation_to_decision": 1.0,
            "decision_to_robot": 1.0,
        },
        abs=US,
    )
    assert sum(sample.stages_ms().values()) == pytest.approx(sample.total_ms, abs=US)
    assert vars(missing) == {
        "no_sensor_origin": 0,
        "sensor_row_missing": 0,
        "publish_not_traced": 0,
    }


def test_a_controller_recommendation_starts_at_its_scan_not_its_newer_odometry() -> None:
    inputs = {"laser_scan": 9, "odometry": 7}
    (sample,), _ = prov.samples({100: T0 + 0.005}, [command(100, 1, inputs)], ROWS, PUBLISHED)
    assert sample.origin == "laser_scan"
    assert sample.published == T0 + 0.0005


def test_repeats_of_a_recommendation_count_once_at_its_first_arrival() -> None:
    # the decision re-issues its winner every 0.1 s sim: the repeats are not reactions
    cmds = [command(100, 1, {"odometry": 7}), command(101, 1, {"odometry": 7}, T0 + 0.104)]
    arrivals = {100: T0 + 0.006, 101: T0 + 0.105}
    samples, _ = prov.samples(arrivals, cmds, ROWS, PUBLISHED)
    assert [round(s.total_ms, 3) for s in samples] == [6.0]


def test_a_superseded_command_leaves_its_recommendation_to_the_first_that_arrived() -> None:
    cmds = [command(100, 1, {"odometry": 7}), command(101, 1, {"odometry": 7})]
    samples, _ = prov.samples({101: T0 + 0.008}, cmds, ROWS, PUBLISHED)
    assert [round(s.total_ms, 3) for s in samples] == [8.0]


def test_commands_without_a_traceable_origin_are_counted_not_sampled() -> None:
    cmds = [
        command(1, 1, {}),  # nothing sensed behind it
        command(2, 2, {"odometry": 8}),  # row pruned before it was read
        command(3, 3, {"laser_scan": True}),  # not an id
    ]
    rows = {**ROWS, ("odometry", 8): prov.SensorRow("odometry", 8, "r1", 71, T0)}
    samples, missing = prov.samples({1: T0, 2: T0, 3: T0}, cmds, rows, PUBLISHED)
    assert samples == []
    assert vars(missing) == {
        "no_sensor_origin": 2,
        "sensor_row_missing": 0,
        "publish_not_traced": 1,
    }
    samples, missing = prov.samples({2: T0}, [cmds[1]], ROWS, PUBLISHED)
    assert missing.sensor_row_missing == 1


def test_share_over_counts_strictly_later_values() -> None:
    assert prov.share_over([1.0, 5.0, 5.1, 60.0], 5.0) == 0.5
    assert prov.share_over([], 5.0) == 0.0


def test_figures_and_targets() -> None:
    samples, _ = prov.samples(
        {100: T0 + 0.0045}, [command(100, 1, {"odometry": 7})], ROWS, PUBLISHED
    )
    figures = latency_figures(samples)
    assert figures["p50"] == figures["p99"] == pytest.approx(4.5, abs=US)
    assert figures["share_over_5ms"] == 0.0 and figures["share_over_50ms"] == 0.0
    assert (target_for(1), target_for(10), target_for(50), target_for(51)) == (
        5.0,
        10.0,
        50.0,
        None,
    )
    assert target_for(5) == 10.0


def stack_run(p99: float) -> dict[str, object]:
    lat = {"p50": 1.0, "p95": 2.0, "p99": p99, "max": 9.0}
    lat |= {"share_over_5ms": 0.0, "share_over_50ms": 0.0}
    return {
        "link": "native",
        "robots": 10,
        "replicas": {},
        "samples": 5,
        "latency_ms": lat,
        "rows_per_s": {},
        "sim_rate": 1.0,
        "processes": {},
        "target_p99_ms": 10.0,
        "target_met": True,
        "stages_ms": {},
    }


def test_the_stacks_p99_is_set_beside_the_floor_and_held_to_twice_it() -> None:
    floor = {"samples": 4, "sent": 4, "p50_ms": 3.0, "p95_ms": 4.0, "p99_ms": 4.0, "cpu_pct": 9.0}
    within = beside_floor(stack_run(8.0), floor)
    assert within["p99_over_floor"] == 2.0 and within["floor_target_met"] is True
    over = beside_floor(stack_run(8.4), floor)
    assert over["p99_over_floor"] == 2.1 and over["floor_target_met"] is False
    line = next(x for x in table([over]) if "the floor" in x and "robots:" in x)
    assert "floor p50/p99 3.00/4.00 ms" in line and "8.40 ms = 2.10x the floor MISS" in line
    # a floor without samples (or one that failed) gives no ratio, and says why
    assert beside_floor(stack_run(8.0), {**floor, "p99_ms": float("nan")})["p99_over_floor"] is None
    failed = beside_floor(stack_run(8.0), {"error": "no figures"})
    assert failed["floor_target_met"] is None
    assert any("floor not measured: no figures" in x for x in table([failed]))
    # a stack run without a sample (a machine too loaded) is a line that says so
    empty = {**failed, "latency_ms": {"share_over_5ms": 0.0, "share_over_50ms": 0.0}}
    assert any("no samples" in x for x in table([empty]))


def test_the_sim_trace_reads_back_what_was_recorded(tmp_path: Path) -> None:
    tracer = Tracer(tmp_path / "trace.csv")
    tracer.record("odom", "r1", 70)
    tracer.record("cmd_vel", "r1", 100)
    tracer.flush()
    tracer.record("scan", "r2", 5)  # not flushed yet: not in the file
    events = read_trace(tmp_path / "trace.csv")
    assert [(e.kind, e.robot, e.ref) for e in events] == [
        ("odom", "r1", 70),
        ("cmd_vel", "r1", 100),
    ]
    assert events[0].wall_ns <= events[1].wall_ns
    tracer.close()
    assert len(read_trace(tmp_path / "trace.csv")) == 3


def test_a_trace_keeps_the_wire_number_and_a_stamp_taken_before_it(tmp_path: Path) -> None:
    # the sim stamps a ROS 2 reading before it goes and names it by its attachment number
    # once the publisher has given it one
    path = tmp_path / "trace.csv"
    tracer = Tracer(path)
    before = Tracer.now()
    tracer.record("scan", "r1", 90, wire=4, wall_ns=before)
    tracer.record(CMD_VEL, "r1", NO_REF, wire=11)
    tracer.close()
    scan, cmd = read_trace(path)
    assert (scan.kind, scan.ref, scan.wire, scan.wall_ns) == ("scan", 90, 4, before)
    assert (cmd.kind, cmd.ref, cmd.wire) == (CMD_VEL, NO_REF, 11)
    assert cmd.wall_ns >= before


def test_the_native_link_joins_by_the_sims_seq_and_the_command_id() -> None:
    sim = [
        TraceEvent("odom", "r1", 70, 1_000_000_000),
        TraceEvent(CMD_VEL, "r1", 100, 1_004_000_000),
        TraceEvent(CMD_VEL, "r1", 100, 1_009_000_000),  # the same command again: first counts
    ]
    published, arrivals = join_trace(sim, None)
    assert published == {("odom", "r1", 70): 1.0}
    assert arrivals == {100: 1.004}


def test_the_ros2_link_joins_through_the_attachment_numbers_the_bridge_traced() -> None:
    # rows keep the attachment number as seq; the sim knows a cmd_vel by its number only
    sim = [
        TraceEvent("odom", "r1", 70, 1_000_000_000, wire=3),
        TraceEvent("odom", "r2", 70, 1_001_000_000, wire=3),
        TraceEvent(CMD_VEL, "r1", NO_REF, 1_004_000_000, wire=8),
        TraceEvent(CMD_VEL, "r2", NO_REF, 1_006_000_000, wire=8),  # same number, other robot
        TraceEvent(CMD_VEL, "r1", NO_REF, 1_007_000_000, wire=9),  # sent without an id
    ]
    bridge = [
        TraceEvent(CMD_VEL, "r1", 100, 1_003_000_000, wire=8),
        TraceEvent(CMD_VEL, "r2", 101, 1_005_000_000, wire=8),
    ]
    published, arrivals = join_trace(sim, bridge)
    assert published == {("odom", "r1", 3): 1.0, ("odom", "r2", 3): 1.001}
    assert arrivals == {100: 1.004, 101: 1.006}


def test_robot_links_are_parsed_in_order_and_an_unknown_one_is_refused() -> None:
    assert parse_links("native") == ("native",)
    assert parse_links("ros2, native,ros2") == ("ros2", "native")
    for bad in ("", "dds", "native,ros3"):
        with pytest.raises(SystemExit, match="--robot-link"):
            parse_links(bad)


def test_layouts_are_parsed_in_order_and_an_unknown_one_is_refused() -> None:
    assert parse_layouts(None) == (None,)
    assert parse_layouts("composed, separate,composed") == ("composed", "separate")
    for bad in ("", "threads", "composed,sep"):
        with pytest.raises(SystemExit, match="--processes"):
            parse_layouts(bad)


def test_the_price_of_separate_processes_is_separate_minus_composed_per_size() -> None:
    def run(
        layout: str, robots: int, p99: float, cpu: float, pss: float, procs: int
    ) -> dict[str, object]:
        names = [f"p{i}" for i in range(procs)]
        usage = {n: {"cpu_percent": cpu / procs, "peak_pss_mb": pss / procs} for n in names}
        return {**stack_run(p99), "robots": robots, "layout": layout, "processes": usage}

    runs = [
        run("composed", 1, 10.0, 20.0, 280.0, 5),
        run("separate", 1, 12.5, 26.0, 400.0, 8),
        run("composed", 10, 14.0, 80.0, 290.0, 5),  # no separate run at 10: no price
    ]
    (price,) = separation_price(runs)
    assert price["robots"] == 1 and price["link"] == "native"
    assert price["p99_ms"] == pytest.approx(2.5) and price["p50_ms"] == pytest.approx(0.0)
    assert price["cpu_percent"] == pytest.approx(6.0) and price["pss_mb"] == pytest.approx(120.0)
    assert price["processes"] == 3
    line = next(x for x in table(runs) if "1 robots:" in x and "p99 +2.50 ms" in x)
    assert "CPU +6 %" in line and "PSS +120 MB" in line and "+3 processes" in line
    assert not separation_price(runs[:1] + runs[2:])


@pytest.mark.parametrize("robots", [1, 10, 50])
def test_the_hall_holds_every_robot_in_its_own_lane(tmp_path: Path, robots: int) -> None:
    hall = write_hall(tmp_path, robots)
    world = load_world(hall.world)
    assert [r.robot_id for r in world.robots] == [lane.robot_id for lane in hall.lanes]
    for lane in hall.lanes:
        for x, y in (lane.a, lane.b):
            assert world.blocked(x, y, world.default_model.footprint_radius_m + 0.1) is None


def test_each_process_reports_the_notifications_it_lost_by_its_last_count(tmp_path: Path) -> None:
    # the lines as the processes log them (docs/ENGINE.md, docs/BRIDGE.md)
    (tmp_path / "controller.log").write_text(
        "2026-11-25T07:41:04.061Z INFO controller engine stopped activations=7130"
        " rules_run=47953 capped_by_n=0 meta_reseeded=0 notifications_lost=3\n"
    )
    (tmp_path / "bridge.log").write_text(
        '2026-11-25T07:40:54.061Z INFO bridge bridge counters messages_in={"odom": 7041}'
        " command_reads=12 command_notes_lost=5 watchdog_stops=0\n"
        "2026-11-25T07:40:59.000Z WARNING bridge something else\n"
        '2026-11-25T07:41:04.061Z INFO bridge bridge counters messages_in={"odom": 9000}'
        " command_reads=14 command_notes_lost=8 watchdog_stops=0\n"
    )
    (tmp_path / "strategy.log").write_text(
        "2026-11-25T07:41:04.061Z INFO strategy engine stopped activations=40\n"
    )
    assert notifications_lost(tmp_path) == {"bridge": 8, "controller": 3}
