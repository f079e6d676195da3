"""pnav.bench.cdr: the CDR micro-benchmark times the link's real round trip (not how fast)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from common import bus, ros2types
from pnav.bench import cdr


@pytest.mark.parametrize("case", cdr.cases(), ids=lambda c: c.name)
def test_each_message_comes_back_from_cdr_as_the_body_it_was_built_from(case: cdr.Case) -> None:
    wire = ros2types.encode(case.type_name, case.build(case.body))
    back = case.convert(ros2types.decode(case.type_name, wire))
    for key, value in back.items():
        if key == "ranges":
            # CDR carries float32: each range within its precision, inf stays inf
            assert len(value) == len(case.body["ranges"])
            for got, sent in zip(value, case.body["ranges"], strict=True):
                assert got == sent if math.isinf(sent) else got == pytest.approx(sent, rel=1e-6)
        else:
            assert value == pytest.approx(case.body[key], rel=1e-6, abs=1e-9), key
    assert bus.unpack(bus.pack(case.body)) == case.body


def test_the_scans_have_the_beams_they_are_named_after() -> None:
    scans = {c.name: c.body for c in cdr.cases() if c.type_name == ros2types.LASER_SCAN}
    assert {name: len(body["ranges"]) for name, body in scans.items()} == {
        "LaserScan 360": 360,
        "LaserScan 720": 720,
    }


def test_a_run_reports_every_step_and_both_sizes_per_message(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "cdr.json"
    assert cdr.main(["--samples", "2", "--repeats", "1", "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    assert [r["message"] for r in result["results"]] == [c.name for c in cdr.cases()]
    for r in result["results"]:
        assert set(r["us"]) == set(cdr.STEPS)
        assert r["cdr_bytes"] > 0 and r["msgpack_bytes"] > 0
        assert r["ros2_us"] == pytest.approx(
            sum(r["us"][s]["median_us"] for s in ("build", "encode", "decode", "convert")), abs=0.05
        )
    assert "LaserScan 720" in capsys.readouterr().out


def test_zero_samples_is_a_usage_error() -> None:
    with pytest.raises(SystemExit):
        cdr.main(["--samples", "0"])
