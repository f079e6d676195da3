"""``pnav zone add | list | remove``: keepout and speed zones, people's rows (CONTRACT.md,
zone), written with their notification so the planner and the bridge apply them at once.

Bad input is refused at the door, before anything is opened, naming the argument: a name
the table would refuse, a speed outside (0, 10] m/s, a polygon that is open, degenerate,
non-finite or intersects itself (common.contract.zones says why, in the table's words).
"""

from __future__ import annotations

import argparse
import json
import sys

import asyncpg

from common.contract import zones
from common.contract.zones import Zone
from common.errors import ContractError, UsageError
from pnav.cli.options import number

speed = number(
    f"a finite speed in (0, {zones.MAX_SPEED_MPS:g}] m/s",
    lambda v: 0 < v <= zones.MAX_SPEED_MPS,
)


def zone_name(text: str) -> str:
    if not zones.NAME.match(text):
        raise argparse.ArgumentTypeError(
            f"must be 1 to 64 letters, digits, '_', '.' or '-', got {text[:80]!r}"
        )
    return text


def polygon(text: str) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """``"x,y; x,y; x,y"`` as (xs, ys), judged as the zone table judges it."""
    try:
        xs, ys = zones.parse_polygon(text, "polygon")
    except ContractError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    problem = zones.polygon_problem(xs, ys)
    if problem is not None:
        raise argparse.ArgumentTypeError(problem)
    return xs, ys


def add_zone_parser(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    zone = commands.add_parser("zone", help="keepout and speed zones: add, list, remove")
    verbs = zone.add_subparsers(dest="zone_command", required=True)
    add = verbs.add_parser("add", help="add a zone (applies at once)")
    add.add_argument("name", type=zone_name, help="the zone's name: [A-Za-z0-9_.-], 1 to 64")
    kind = add.add_mutually_exclusive_group(required=True)
    kind.add_argument("--keepout", action="store_true", help="the planner never routes here")
    kind.add_argument(
        "--speed-limit", type=speed, metavar="V", help="cap the linear speed here at V m/s"
    )
    add.add_argument(
        "--polygon",
        type=polygon,
        required=True,
        help='"x,y; x,y; x,y; ..." in the map frame, m: 3 to 100 vertices in order, '
        "closed implicitly (do not repeat the first)",
    )
    add.add_argument("--robot", help="only this robot (default: every robot)")
    add.add_argument("--description", default="", help="for people, one line")
    listing = verbs.add_parser("list", help="the zones, by name")
    listing.add_argument("--json", action="store_true", help="JSON, one list")
    remove = verbs.add_parser("remove", help="remove a zone (applies at once)")
    remove.add_argument("name", type=zone_name)


def zone_of(args: argparse.Namespace) -> Zone:
    """The row ``pnav zone add`` asks for, checked as the table would (naming the option)."""
    xs, ys = args.polygon
    kind = zones.KEEPOUT if args.keepout else zones.SPEED_LIMIT
    zone = Zone(args.name, kind, xs, ys, args.speed_limit, args.robot, args.description)
    try:
        zones.check_zone(zone)
    except ContractError as exc:
        option = {"robot_id": "--robot", "description": "--description"}
        field = str(exc).split()[1]
        raise ContractError(f"{option.get(field, field)}: {exc}") from None
    return zone


def show(rows: list[Zone], as_json: bool) -> None:
    if as_json:
        json.dump([z.image() for z in rows], sys.stdout)
        print()
        return
    if not rows:
        print("no zones")
        return
    for z in rows:
        cap = f"{z.max_speed_mps:g} m/s" if z.max_speed_mps is not None else "-"
        robots = z.robot_id or "all robots"
        vertices = "; ".join(f"{x:g},{y:g}" for x, y in zip(z.xs, z.ys, strict=True))
        print(f"{z.name:<20} {z.kind:<12} {cap:<10} {robots:<12} {vertices}")


async def run_zone(args: argparse.Namespace) -> int:
    from pnav.cli import stack_commands

    zone = zone_of(args) if args.zone_command == "add" else None
    rt = await stack_commands.open_runtime()
    try:
        db = rt.database
        with stack_commands.refusal_as_contract_error():
            if zone is not None:
                try:
                    await zones.add_zone(db, zone)
                except asyncpg.UniqueViolationError:
                    raise ContractError(
                        f"name: a zone named {zone.name!r} exists; remove it first "
                        f"(pnav zone remove {zone.name})"
                    ) from None
                print(f"zone {zone.name} added ({zone.kind})")
                return 0
            if args.zone_command == "remove":
                if not await zones.remove_zone(db, args.name):
                    raise UsageError(f"name: no zone named {args.name!r} (pnav zone list)")
                print(f"zone {args.name} removed")
                return 0
            show(await zones.read_zones(db), args.json)
            return 0
    finally:
        await rt.close()
