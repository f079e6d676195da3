"""The sensor writer's memory of its recent rows (services/bridge/replay.py), step by step."""

from __future__ import annotations

from common.contract import keys
from services.bridge.replay import Replay
from services.bridge.sensor_payloads import Collision, Odometry
from services.bridge.sensor_tables import SENSOR_TABLES


class Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def _odom(seq: int) -> Odometry:
    return Odometry("r1", float(seq), seq, 0.0, 0.0, 0.0, 0.0, 0.0)


def test_rows_are_remembered_for_the_window_of_the_writers_own_writes() -> None:
    clock = Clock()
    replay = Replay(list(SENSOR_TABLES.values()), window_s=2.0, clock=clock)
    replay.written(keys.ODOMETRY, [(1, "r1"), (2, "r1")], [_odom(1), _odom(2)])
    assert replay.remembered(keys.ODOMETRY) == [1, 2]
    clock.now += 1.5
    replay.written(keys.ODOMETRY, [(3, "r1")], [_odom(3)])
    assert replay.remembered(keys.ODOMETRY) == [1, 2, 3]  # 1.5 s old: within the window
    clock.now += 1.0
    replay.written(keys.ODOMETRY, [(4, "r1")], [_odom(4)])
    assert replay.remembered(keys.ODOMETRY) == [3, 4]  # the first batch is 2.5 s old
    clock.now += 60.0  # an outage: nothing is written, so nothing is forgotten
    assert replay.remembered(keys.ODOMETRY) == [3, 4]


def test_only_renewed_connections_make_a_table_restore() -> None:
    replay = Replay(list(SENSOR_TABLES.values()), clock=Clock())
    replay.written(keys.ODOMETRY, [(1, "r1")], [_odom(1)])
    assert not replay.pending(keys.ODOMETRY)  # written and connected: nothing to restore
    replay.connections_renewed()
    assert replay.pending(keys.ODOMETRY)
    assert replay.pending(keys.LASER_SCAN)  # every table: the server may have restarted


def test_durable_collision_events_are_not_remembered() -> None:
    replay = Replay(list(SENSOR_TABLES.values()), clock=Clock())
    event = Collision("r1", 1.0, seq=1, other="wall", x=0.0, y=0.0, run="run")
    replay.written(keys.COLLISION_EVENT, [(1, "r1")], [event])
    replay.connections_renewed()
    assert replay.remembered(keys.COLLISION_EVENT) == []
    assert not replay.pending(keys.COLLISION_EVENT)  # committed synchronously: never lost


def test_a_batch_whose_ids_do_not_pair_with_its_records_is_not_remembered() -> None:
    replay = Replay(list(SENSOR_TABLES.values()), clock=Clock())
    replay.written(keys.ODOMETRY, [(1, "r1")], [_odom(1), _odom(2)])  # a row short
    replay.written(keys.ODOMETRY, [(1, "r2"), (2, "r1")], [_odom(1), _odom(2)])  # swapped
    assert replay.remembered(keys.ODOMETRY) == []
