"""``python -m pnav.bench.bridge``: the command line, and the run of the legs in order."""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import platform
import sys
from typing import Any

import psutil

import pnav.bench.bridge as package
from pnav.bench.bridge import legs
from pnav.bench.bridge.bridge_rig import BenchStack
from pnav.bench.bridge.leg_report import report
from pnav.bench.bridge.player import Player
from pnav.bench.bridge.row_latency import Notifications, summary_ms

PROG = "python -m pnav.bench.bridge"


async def run(args: argparse.Namespace) -> dict[str, Any]:
    robots = [f"bench{i}" for i in range(args.robots)]
    async with BenchStack(robots) as stack:
        ready_s = await stack.start_bridge()
        notes = Notifications(stack.session)
        try:
            player = Player(stack.session, robots)
            await asyncio.sleep(1.0)  # the bridge's subscriptions are in place
            bridge = psutil.Process(stack.pid)
            cpu_s, sent = _cpu_s(bridge), len(player.sent)
            steady = await legs.steady(
                stack.conn, player, notes, args.seconds, args.odom_hz, args.scan_hz
            )
            # everything the bridge did for the steady leg's messages: validate, write,
            # notify, and its own housekeeping meanwhile
            cpu_s, sent = _cpu_s(bridge) - cpu_s, len(player.sent) - sent
            steady["bridge_cpu_s"] = round(cpu_s, 3)
            steady["bridge_cpu_us_per_message"] = round(1e6 * cpu_s / sent, 1) if sent else None
            burst = await legs.burst(stack.conn, player, notes, args.burst)
        finally:
            notes.close()
        cmd = await legs.commands(stack.conn, stack.session, robots[0], min(args.seconds, 5.0))
        hop = await asyncio.to_thread(legs.zenoh_hop, stack.settings)
        exit_code = await stack.stop_bridge()
    return {
        "command": " ".join([PROG, *sys.argv[1:]]),
        "machine": {
            "cpus": os.cpu_count(),
            "platform": platform.platform(),
            "python": platform.python_version(),
        },
        "robots": len(robots),
        "bridge_ready_s": round(ready_s, 3),
        "steady": steady,
        "burst": burst,
        "command_notification_to_cmd_vel": summary_ms(cmd),
        "zenoh_hop": summary_ms(hop),
        "bridge_exit_code": exit_code,
    }


def _cpu_s(process: psutil.Process) -> float:
    times = process.cpu_times()
    return float(times.user + times.system)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog=PROG, description=package.__doc__)
    parser.add_argument("--seconds", type=float, default=10.0, help="steady phase length")
    parser.add_argument("--robots", type=int, default=1)
    parser.add_argument("--odom-hz", type=float, default=30.0, help="steady odometry rate")
    parser.add_argument("--scan-hz", type=float, default=5.0, help="steady scan rate")
    parser.add_argument("--burst", type=int, default=3000, help="odometry messages in the burst")
    parser.add_argument("--json", help="also write the JSON result to this file")
    args = parser.parse_args(argv)
    result = asyncio.run(run(args))
    print(report(result))
    text = json.dumps(result, indent=2)
    print(text)
    if args.json:
        with open(args.json, "w") as f:
            f.write(text + "\n")
    return 0 if result["bridge_exit_code"] == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
