"""``python -m pnav.record FILE [--encoding ros2]``: record the running stack into FILE until
SIGINT/SIGTERM.

Started by ``pnav up --record FILE`` and ``pnav demo --record FILE`` as a supervised process,
with the stack's environment (PNAV_DATABASE_URL, PNAV_ZENOH_*). A restart after a crash does
not overwrite the part already written: it records into ``FILE-2.mcap``, ``FILE-3.mcap``...
"""

from __future__ import annotations

import argparse
import asyncio
import dataclasses
import logging
import sys
from pathlib import Path

from common import bus
from common.config import ServiceConfig
from common.contract import keys
from common.runtime import Runtime, run_service
from pnav.record import ENCODINGS
from pnav.record.recorder import Recorder
from pnav.record.ros2 import Ros2Recorder
from pnav.record.source import RecordSource

log = logging.getLogger("pnav.record")


def free_path(path: Path) -> Path:
    """``path``, or the first of ``stem-2.mcap``, ``stem-3.mcap``... that does not exist."""
    candidate, n = path, 1
    while candidate.exists():
        n += 1
        candidate = path.with_name(f"{path.stem}-{n}{path.suffix}")
    return candidate


async def record(
    path: Path, config: ServiceConfig, stop: asyncio.Event, encoding: str = "foxglove"
) -> None:
    # a recorder only watches: it never holds up a lockstep sim
    rt = await Runtime.open(dataclasses.replace(config, lockstep=()))
    target = free_path(path)
    kind = Ros2Recorder if encoding == "ros2" else Recorder
    recorder = kind(target, RecordSource(rt.database.pool), rt.clock)

    def on_notification(key: str, payload: bytes) -> None:
        try:
            recorder.note(bus.Notification.decode(key, payload))
        except ValueError:
            log.debug("ignored a malformed notification on %s", key)

    subscriber = bus.subscribe(rt.zenoh, keys.NOTIFY_ALL, on_notification)
    log.info("recording to %s (%s encoding)", target, encoding)
    try:
        await recorder.run(stop)
    finally:
        subscriber.undeclare()
        recorder.close()
        await rt.close()
        log.info(
            "recorded %d messages on %d topics to %s",
            recorder.counts.messages,
            len(recorder.counts.per_topic),
            target,
        )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m pnav.record", description=__doc__)
    parser.add_argument("file", type=Path, help="the MCAP file to write")
    parser.add_argument("--encoding", choices=ENCODINGS, default="foxglove")
    args = parser.parse_args(argv)
    return run_service(
        "recorder", lambda config, stop: record(args.file, config, stop, args.encoding)
    )


if __name__ == "__main__":
    sys.exit(main())
