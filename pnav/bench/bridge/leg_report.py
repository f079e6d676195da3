"""The benchmark's result for people: one line per leg."""

from __future__ import annotations

from typing import Any


def report(result: dict[str, Any]) -> str:
    def line(name: str, s: dict[str, float]) -> str:
        return (
            f"  {name:28s} n={s['n']:<6} p50={s['p50_ms']:.2f} ms"
            f"  p99={s['p99_ms']:.2f} ms  max={s['max_ms']:.2f} ms"
        )

    st, bu = result["steady"], result["burst"]
    return "\n".join(
        [
            f"bridge benchmark: {result['robots']} robot(s), {result['machine']['cpus']} CPUs",
            f"steady ({st['seconds']} s, odom {st['odom_hz']:g} Hz + scan {st['scan_hz']:g} Hz"
            f" per robot): the bridge {st['bridge_cpu_s']} CPU s,"
            f" {st['bridge_cpu_us_per_message']} us a message",
            line("odom -> notification", st["odom_to_notification"]),
            line("scan -> notification", st["scan_to_notification"]),
            line("odom -> received_at", st["odom_to_received_at"]),
            line("scan -> received_at", st["scan_to_received_at"]),
            f"burst: {bu['rows']} rows in {bu['seconds']} s = {bu['rows_per_s']} rows/s,"
            f" {bu['notifications']} notifications (one per batch)",
            line("burst odom -> notification", bu["odom_to_notification"]),
            "commands (20 Hz):",
            line("notification -> cmd_vel", result["command_notification_to_cmd_vel"]),
            "for scale, one Zenoh publication through the router (30 Hz):",
            line("zenoh hop", result["zenoh_hop"]),
        ]
    )
