"""A ROS LaserScan's NaN and infinite ranges (REP 117) become what the contract's laser_scan
row means (services/bridge/ros2msgs.py), and the scan is stored, not refused."""

from __future__ import annotations

import math
from collections import Counter

import numpy as np
import pytest

from services.bridge import ros2msgs
from services.bridge import sensor_payloads as messages
from services.sim import ros2wire
from tests.unit.bridge import payloads

INF, NAN = math.inf, math.nan


def test_rep117_values_read_as_the_contract_means_them() -> None:
    ranges = np.array([1.0, INF, -INF, NAN, 0.0, 0.05, 3.6, 1e9, 3.5, 0.12])
    counts: Counter[str] = Counter()
    out = ros2msgs.contract_ranges(ranges, 0.12, 3.5, counts)
    # +inf stays "nothing in range"; -inf is an obstacle nearer than range_min, which reads
    # range_min as the sim's too-close hits do; NaN and what LaserScan says to discard
    # (below range_min, such as an LDS-01's 0.0, or beyond range_max) carry no return
    assert out.tolist() == [1.0, INF, 0.12, INF, INF, INF, INF, INF, 3.5, 0.12]
    assert counts == {"too_close": 1, "nan": 1, "below_range": 2, "beyond_range": 2}


def test_a_mostly_nan_scan_is_a_valid_row() -> None:
    raw = [NAN] * 300 + [1.0] * 59 + [-INF]
    msg = ros2wire.scan_msg(payloads.scan(ranges=raw), "r1/base_scan")
    counts: Counter[str] = Counter()
    record = messages.parse_scan("r1", ros2msgs.scan_body(msg, 1, counts), 360)
    assert record.ranges[:300] == [INF] * 300
    assert record.ranges[300:359] == [1.0] * 59 and record.ranges[359] == 0.12
    assert counts == {"nan": 300, "too_close": 1}


def test_a_nan_range_limit_is_still_refused() -> None:
    msg = ros2wire.scan_msg(payloads.scan(range_max=NAN), "r1/base_scan")
    body = ros2msgs.scan_body(msg, 1)
    with pytest.raises(messages.MalformedMessage) as refused:
        messages.parse_scan("r1", body, 360)
    assert refused.value.reason == messages.NOT_FINITE
