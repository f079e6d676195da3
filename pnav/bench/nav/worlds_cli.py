"""``pnav worlds generate``: write a suite of BARN-style benchmark worlds.

    pnav worlds generate --out DIR [--count N] [--seed S] [--levels easy,medium,hard] [--png]
                         [--protocol default|barn|dynabarn] [--model NAME]

writes N worlds per level (world i of a level drawn with seed S * 1000 + i) as DIR/NAME.yaml
plus DIR/maps/NAME.{yaml,pgm}, with --png a preview DIR/preview/NAME.png of each, and
DIR/SUITE.md (the command, the levels, a table of the worlds); prints the same table.
``--protocol barn`` writes BARN-protocol worlds for ``--model`` (``pnav.bench.nav.barn``);
``--protocol dynabarn`` the same corridor crossed by moving obstacles
(``pnav.bench.nav.dynabarn``). This module imports nothing heavy at load time: ``pnav``'s
parser is built on every command.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from common.errors import UsageError

if TYPE_CHECKING:
    from pnav.bench.nav.suitefile import SuiteFiles

DEFAULT_LEVELS = "easy,medium,hard"
PROTOCOLS = ("default", "barn", "dynabarn")
BARN_DEFAULT_MODEL = "jackal"  # the BARN Challenge's robot


def add_worlds_parser(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add ``worlds`` (with its ``generate`` command) to the ``pnav`` sub-commands."""
    worlds = subparsers.add_parser("worlds", help="benchmark worlds (BARN-style generator)")
    actions = worlds.add_subparsers(dest="worlds_command", metavar="ACTION", required=True)
    gen = actions.add_parser("generate", help="write a suite of generated worlds")
    gen.add_argument("--out", type=Path, required=True, help="folder to write the worlds to")
    gen.add_argument("--count", type=int, default=20, help="worlds per level (20)")
    gen.add_argument("--seed", type=int, default=0, help="suite seed (0)")
    gen.add_argument(
        "--levels", default=DEFAULT_LEVELS, help=f"comma-separated levels ({DEFAULT_LEVELS})"
    )
    gen.add_argument("--png", action="store_true", help="also write preview/NAME.png per world")
    gen.add_argument(
        "--protocol",
        choices=PROTOCOLS,
        default="default",
        help="default: the obstacles are in the map, for the Burger; barn: BARN's protocol "
        "(obstacles only in the sim world, goal 10 m ahead, success within 1 m, BARN's time "
        "limit), for --model (jackal); dynabarn: BARN's corridor with no standing obstacle, "
        "crossed by moving obstacles at 0.1-1.0 m/s (seen only by the lidar)",
    )
    gen.add_argument(
        "--model",
        help="robot model the worlds are made for (--protocol barn or dynabarn; default jackal)",
    )


def command_line(args: argparse.Namespace) -> str:
    """The command that writes exactly this suite (recorded in the files it writes)."""
    line = (
        f"pnav worlds generate --out {args.out} --count {args.count} --seed {args.seed} "
        f"--levels {args.levels}"
    )
    protocol = getattr(args, "protocol", "default")
    if protocol != "default":
        line += f" --protocol {protocol} --model {args.model or BARN_DEFAULT_MODEL}"
    return line + (" --png" if args.png else "")


# the comment on top of every world file of a suite, per protocol
HEADERS = {
    "default": (
        "BARN-style benchmark world, written by `{command}`.\n"
        "Generated: do not edit (the reference path is computed for this map). "
        "Fields: docs/NAVBENCH.md."
    ),
    "barn": (
        "BARN-protocol benchmark world, written by `{command}`.\n"
        "Generated: do not edit (the reference path is computed for this map and these "
        "obstacles). Fields: docs/NAVBENCH.md."
    ),
    "dynabarn": (
        "Dynamic BARN-protocol benchmark world, written by `{command}`.\n"
        "Generated: do not edit (the movers are drawn from the seed). Fields: docs/NAVBENCH.md."
    ),
}


def world_header(command: str, protocol: str = "default") -> str:
    """The comment on top of every world file of a suite written by ``command``."""
    return HEADERS[protocol].replace("{command}", command)


def checked_levels(args: argparse.Namespace, known: Sequence[str]) -> list[str]:
    """``--levels``, ``--count`` and ``--seed`` checked (UsageError); the levels."""
    levels = [lv.strip() for lv in str(args.levels).split(",") if lv.strip()]
    unknown = [lv for lv in levels if lv not in known]
    if not levels or unknown:
        raise UsageError(
            f"--levels: unknown {', '.join(unknown) or '(none)'}; known: {', '.join(known)}"
        )
    if not 1 <= args.count <= 1000:
        raise UsageError(f"--count must be within 1..1000, got {args.count}")
    if args.seed < 0:
        raise UsageError(f"--seed must not be negative, got {args.seed}")
    return levels


def generate(args: argparse.Namespace) -> int:
    protocol = getattr(args, "protocol", "default")
    if protocol == "default" and getattr(args, "model", None):
        raise UsageError(
            "--model needs --protocol barn or dynabarn (the default protocol's worlds are for "
            "the Burger)"
        )
    worlds, files = generated_suite(args, protocol)
    command = command_line(args)
    header = world_header(command, protocol)
    files.write_suite(worlds, args.out, command=command, header=header, png=args.png)
    return finish(args.out, [w.name for w in worlds])


def generated_suite(
    args: argparse.Namespace, protocol: str
) -> tuple[Sequence[Any], SuiteFiles[Any]]:
    """The worlds ``args`` ask for, and how their protocol writes them: ``barn``, the same
    files with the obstacles as world obstacles (barnfile.py); ``dynabarn``, BARN's corridor
    crossed by movers (dynabarnfile.py); else the default protocol (generatedfile.py)."""
    from pnav.bench.nav.robots import resolve_model

    if protocol == "barn":
        from pnav.bench.nav import barn, barnfile

        levels = checked_levels(args, list(barn.LEVELS))
        robot = resolve_model(args.model or BARN_DEFAULT_MODEL)
        return barn.generate_barn_suite(levels, args.count, args.seed, robot), barnfile.SUITE_FILES
    if protocol == "dynabarn":
        from pnav.bench.nav import dynabarn, dynabarnfile

        levels = checked_levels(args, list(dynabarn.LEVELS))
        robot = resolve_model(args.model or BARN_DEFAULT_MODEL)
        suite = dynabarn.generate_dynabarn_suite(levels, args.count, args.seed, robot)
        return suite, dynabarnfile.SUITE_FILES
    from pnav.bench.nav import generatedfile, generator

    levels = checked_levels(args, list(generator.LEVELS))
    return generator.generate_suite(levels, args.count, args.seed), generatedfile.SUITE_FILES


def finish(out: Path, written_names: Sequence[str]) -> int:
    """Say what was written, and warn of other benchmark worlds in the folder."""
    from pnav.bench.nav.worldfile import is_benchmark_world

    count = len(written_names)
    print(f"\nwrote {count} world{'s' if count != 1 else ''} to {out}")
    written = set(written_names)
    stale = [p.name for p in sorted(out.glob("*.yaml")) if p.stem not in written]
    stale = [n for n in stale if is_benchmark_world(out / n)]
    if stale:
        # a suite is every benchmark world in the folder: old ones would join it
        print(f"warning: {out} also holds other benchmark worlds: {', '.join(stale)}")
    return 0


def run_worlds(args: argparse.Namespace) -> int:
    """Run a parsed ``pnav worlds ...`` command; the exit status."""
    if args.worlds_command == "generate":
        return generate(args)
    raise AssertionError(f"unhandled worlds command {args.worlds_command}")


def main(argv: list[str] | None = None) -> int:
    """``python -m pnav.bench.nav.worlds_cli generate ...``: the same, without ``pnav``."""
    parser = argparse.ArgumentParser(prog="pnav")
    add_worlds_parser(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(["worlds", *(sys.argv[1:] if argv is None else argv)])
    try:
        return run_worlds(args)
    except UsageError as exc:
        print(f"pnav: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
