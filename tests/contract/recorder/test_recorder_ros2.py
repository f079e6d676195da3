"""The recorder in ROS 2 encoding (``python -m pnav.record FILE --encoding ros2``) against the
contract: the same small mission as test_recorder.py, read back by a reader that knows no ROS
type in advance: each channel's messages are decoded with the types parsed from the ros2msg
schema text the channel names (rosbags' .msg parser into an empty type store), as
``ros2 bag play`` and Foxglove do.
"""

from __future__ import annotations

import signal
from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from common.config import ZenohSettings
from common.runtime import Runtime
from pnav._testing import ClockPlayer
from pnav.cli import program as cli
from pnav.record import ros2
from tests.contract.recorder.test_recorder import ROBOT, start_recorder, write_mission

pytestmark = pytest.mark.timeout(90)

DOC = Path(__file__).resolve().parents[3] / "docs" / "RECORDING.md"
SEPARATOR = "=" * 80 + "\n"


def decoder_of(name: str, text: str) -> Any:
    """A CDR decoder of ``name`` built only from its ros2msg schema text."""
    store = get_typestore(Stores.EMPTY)
    sections = text.split(SEPARATOR)
    types = dict(get_types_from_msg(sections[0], name))
    for section in sections[1:]:
        header, _, body = section.partition("\n")
        assert header.startswith("MSG: ") and header.count("/") == 2, header  # pkg/msg/Name
        types.update(get_types_from_msg(body, header.removeprefix("MSG: ")))
    store.register(types)
    return lambda data: store.deserialize_cdr(data, name)


async def test_a_ros2_recording_decodes_every_message_with_the_schema_its_channel_names(
    client: Runtime,
    clock: ClockPlayer,
    db_url: str,
    zenoh_settings: ZenohSettings,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    path = tmp_path / "run.mcap"
    recorder = await start_recorder(path, db_url, zenoh_settings, "ros2")
    try:
        stamps = await write_mission(client)
    finally:
        recorder.send_signal(signal.SIGTERM)
        output = (await recorder.stdout.read()).decode()
        code = await recorder.wait()
    assert code == 0, output

    with path.open("rb") as stream:
        reader = make_reader(stream)
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None  # closed cleanly
        decoders = {s.id: decoder_of(s.name, s.data.decode()) for s in summary.schemas.values()}
        messages: dict[str, list[tuple[int, Any]]] = {}
        for schema, channel, message in reader.iter_messages():
            assert schema is not None and schema.encoding == "ros2msg", channel.topic
            assert channel.message_encoding == "cdr", channel.topic
            value = decoders[schema.id](message.data)
            messages.setdefault(channel.topic, []).append((message.log_time, value))

    expected = {t.replace("{ns}", ROBOT): name for t, name in ros2.TOPICS.items()}
    assert set(messages) == set(expected)
    for channel in summary.channels.values():
        assert summary.schemas[channel.schema_id].name == expected[channel.topic]
    doc = DOC.read_text()
    for topic, name in ros2.TOPICS.items():  # the doc names what the code writes
        assert f"| `{topic}` | {name} |" in doc, topic

    low, high = stamps["all"]  # log times are sim time
    for topic, entries in messages.items():
        for log_time, _ in entries:
            assert low * 1e9 - 1 <= log_time <= high * 1e9 + 1, (topic, log_time)
    odom = messages[f"/{ROBOT}/odom"]
    assert [t for t, _ in odom] == [round(s * 1e9) for s in stamps["odometry"]]
    assert [round(m.pose.pose.position.x, 6) for _, m in odom] == [0.0, 0.1, 0.2]
    assert odom[0][1].header.frame_id == f"{ROBOT}/odom"
    assert odom[0][1].child_frame_id == f"{ROBOT}/base_link"
    tf = messages["/tf"][2][1].transforms
    assert [(t.header.frame_id, t.child_frame_id) for t in tf] == [
        ("map", f"{ROBOT}/odom"),
        (f"{ROBOT}/odom", f"{ROBOT}/base_link"),
    ]
    assert round(tf[1].transform.translation.x, 6) == 0.2
    scan = messages[f"/{ROBOT}/scan"][0][1]
    assert len(scan.ranges) == 360 and scan.header.frame_id == f"{ROBOT}/base_link"
    assert (scan.header.stamp.sec, scan.header.stamp.nanosec) == (10, 0)
    grid = messages["/map"][0][1]
    assert (grid.info.width, grid.info.height, grid.info.resolution) == (4, 3, 0.5)
    assert list(grid.data[:4]) == [0, 0, 100, -1]  # the contract's unknown (255) is -1
    battery = messages[f"/{ROBOT}/battery_state"][0][1]
    assert round(battery.percentage, 4) == 0.5005 and battery.power_supply_status == 2
    plan = messages[f"/{ROBOT}/plan"][0][1]
    assert [round(p.pose.position.x, 3) for p in plan.poses] == [0.0, 1.5, 3.0]
    twist = messages[f"/{ROBOT}/cmd_vel"][0][1]
    assert (twist.linear.x, twist.angular.z) == (0.1, 0.5)

    assert cli.main(["record", "info", str(path)]) == 0
    text = capsys.readouterr().out
    assert "robots: r1" in text and "sim time 10.00 to 10.21 s" in text  # the last: cmd_vel
    assert "sensor_msgs/msg/LaserScan (cdr)" in text and "/r1/cmd_vel" in text


def test_encoding_needs_a_recording(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["demo", "--encoding", "ros2"]) == 2
    assert "add --record FILE" in capsys.readouterr().err
