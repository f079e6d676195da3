"""The dashboard's attacks (``pnav bench faults``, kind ``dashboard``): what a hostile page or
client sends the stack's dashboard, which must refuse it and go on serving. ``deep-params``
posts a strategy whose params nest 500 deep and inserts one as a database client would;
``dns-rebinding`` posts a goal and opens the websocket as a page of evil.example pointed at
127.0.0.1 would. Anything let through is a breach."""

from __future__ import annotations

import asyncio
from typing import TYPE_CHECKING

import asyncpg

from common.contract import keys
from pnav.bench.faults.context import ROBOT, Context, Injection

if TYPE_CHECKING:
    from pnav.bench.faults.catalogue import Fault


async def _http(
    port: int, method: str, path: str, host: str, *, origin: str | None = None, body: str = ""
) -> tuple[int, str]:
    """One HTTP/1.1 request to the dashboard on 127.0.0.1 with these Host and Origin headers,
    as a browser sends them (a raw request: no client library rewrites Host); its status
    and body. A websocket handshake is a GET with ``Upgrade: websocket``."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    try:
        lines = [f"{method} {path} HTTP/1.1", f"Host: {host}", "Connection: close"]
        if origin is not None:
            lines.append(f"Origin: {origin}")
        if path == "/ws":
            lines[2] = "Connection: Upgrade"
            lines += [
                "Upgrade: websocket",
                "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==",
                "Sec-WebSocket-Version: 13",
            ]
        data = body.encode()
        if method == "POST":
            lines += ["Content-Type: application/json", f"Content-Length: {len(data)}"]
        writer.write(("\r\n".join(lines) + "\r\n\r\n").encode() + data)
        await writer.drain()
        status = int((await asyncio.wait_for(reader.readline(), 20)).split()[1])
        if path == "/ws":
            return status, ""
        answer = await asyncio.wait_for(reader.read(), 20)
        return status, answer.partition(b"\r\n\r\n")[2].decode(errors="replace")
    finally:
        writer.close()


def _nested(depth: int) -> str:
    return '{"k": ' + "[" * (depth - 1) + "1" + "]" * (depth - 1) + "}"


async def attack_dashboard(fault: Fault, ctx: Context) -> Injection:
    url = ctx.stack.dashboard_url
    if url is None:
        return Injection(notes=["the stack serves no dashboard"], breaches=["not tried"])
    port = int(url.rstrip("/").rsplit(":", 1)[1])
    out = Injection()
    refused: list[str] = []
    if fault.name == "deep-params":
        await _deep_params(port, ctx, out, refused)
    else:
        await _dns_rebinding(port, ctx, out, refused)
    own = f"127.0.0.1:{port}"
    for path in ("/api/strategies", "/api/state"):
        status, _ = await _http(port, "GET", path, own)
        if status != 200:
            out.breaches.append(f"the dashboard no longer serves: GET {path} {status}")
    out.refused = "; ".join(refused)
    return out


async def _deep_params(port: int, ctx: Context, out: Injection, refused: list[str]) -> None:
    code = "DEEP_PARAMS"
    body = f'{{"code": "{code}", "params": {_nested(500)}}}'
    status, answer = await _http(port, "POST", "/api/strategies", f"127.0.0.1:{port}", body=body)
    if 400 <= status < 500:
        refused.append(f"POST {status} {answer[:120]}")
    else:
        out.breaches.append(f"POST /api/strategies answered {status}")
    try:
        await ctx.rt.database.write(
            keys.STRATEGY,
            None,
            "INSERT INTO strategy (code, params) VALUES ($1, $2::text::jsonb)",
            code,
            _nested(500),
        )
    except asyncpg.CheckViolationError as exc:
        refused.append(f"INSERT refused ({exc.constraint_name})")
    else:
        out.breaches.append("INSERT accepted")
    rows = await ctx.rt.database.pool.fetchval(
        f"SELECT count(*) FROM {keys.STRATEGY} WHERE code = $1", code
    )
    if rows:
        out.breaches.append(f"{rows} {code} row(s) committed")


async def _dns_rebinding(port: int, ctx: Context, out: Injection, refused: list[str]) -> None:
    host = f"evil.example:{port}"
    before = await ctx.rt.database.pool.fetchval(f"SELECT count(*) FROM {keys.GOAL}")
    x, y = ctx.goal
    body = f'{{"x": {x + 1.0}, "y": {y}}}'
    goal = f"/api/robots/{ROBOT}/goal"
    status, _ = await _http(port, "POST", goal, host, origin=f"http://{host}", body=body)
    for what, got in (
        ("goal POST", status),
        ("websocket", (await _http(port, "GET", "/ws", host, origin=f"http://{host}"))[0]),
        (
            "https-origin websocket",
            (
                await _http(
                    port, "GET", "/ws", f"127.0.0.1:{port}", origin=f"https://127.0.0.1:{port}"
                )
            )[0],
        ),
    ):
        if got == 403:
            refused.append(f"{what} 403")
        else:
            out.breaches.append(f"{what} answered {got}")
    after = await ctx.rt.database.pool.fetchval(f"SELECT count(*) FROM {keys.GOAL}")
    if after != before:
        out.breaches.append(f"{after - before} goal row(s) written")
