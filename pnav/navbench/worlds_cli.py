"""``pnav worlds generate``: write a suite of BARN-style benchmark worlds.

    pnav worlds generate --out DIR [--count N] [--seed S] [--levels easy,medium,hard] [--png]
                         [--protocol default|barn|dynabarn] [--model NAME]

writes N worlds per level (world i of a level drawn with seed S * 1000 + i) as DIR/NAME.yaml
plus DIR/maps/NAME.{yaml,pgm}, with --png a preview DIR/preview/NAME.png of each, and
DIR/SUITE.md (the command, the levels, a table of the worlds); prints the same table.
``--protocol barn`` writes BARN-protocol worlds for ``--model`` (``pnav.navbench.barn``);
``--protocol dynabarn`` the same corridor crossed by moving obstacles
(``pnav.navbench.dynabarn``). This module imports nothing heavy at load time: ``pnav``'s
parser is built on every command.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

from common.errors import UsageError

if TYPE_CHECKING:
    from pnav.navbench.difficulty import Difficulty
    from pnav.navbench.generator import GeneratedWorld
    from pnav.navbench.search import ReferencePath


class SuiteWorld(Protocol):
    """What the per-level means need of a generated world, of either protocol."""

    @property
    def level(self) -> str: ...
    @property
    def fill_ratio(self) -> float: ...
    @property
    def reference(self) -> ReferencePath: ...
    @property
    def difficulty(self) -> Difficulty: ...


DEFAULT_LEVELS = "easy,medium,hard"
PROTOCOLS = ("default", "barn", "dynabarn")
BARN_DEFAULT_MODEL = "jackal"  # the BARN Challenge's robot
COLUMNS = ("world", "level", "seed", "tries", "fill", "L_ref m", "OT s", "limit s")
METRIC_COLUMNS = ("closest m", "visib m", "dispers", "char m", "tortuos")


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


def table_rows(worlds: Sequence[GeneratedWorld]) -> list[list[str]]:
    from pnav.navbench.metrics import default_time_limit, optimal_time

    rows = []
    for w in worlds:
        length = w.reference.length_m
        d = w.difficulty
        rows.append(
            [
                w.name,
                w.level,
                str(w.seed),
                str(w.attempts),
                f"{w.fill_ratio:.3f}",
                f"{length:.2f}",
                f"{optimal_time(length):.1f}",
                f"{default_time_limit(length):.0f}",
                f"{d.closest_obstacle_m:.3f}",
                f"{d.avg_visibility_m:.2f}",
                f"{d.dispersion:.2f}",
                f"{d.characteristic_dimension_m:.2f}",
                f"{d.tortuosity:.3f}",
            ]
        )
    return rows


def level_means(worlds: Sequence[SuiteWorld]) -> list[list[str]]:
    """Per level: the mean fill, reference length and difficulty metrics."""
    rows = []
    for level in dict.fromkeys(w.level for w in worlds):
        group = [w for w in worlds if w.level == level]

        def mean(values: Sequence[float]) -> float:
            return sum(values) / len(values)

        d = [w.difficulty for w in group]
        rows.append(
            [
                f"{level} ({len(group)})",
                f"{mean([w.fill_ratio for w in group]):.3f}",
                f"{mean([w.reference.length_m for w in group]):.2f}",
                f"{mean([x.closest_obstacle_m for x in d]):.3f}",
                f"{mean([x.avg_visibility_m for x in d]):.2f}",
                f"{mean([x.dispersion for x in d]):.2f}",
                f"{mean([x.characteristic_dimension_m for x in d]):.2f}",
                f"{mean([x.tortuosity for x in d]):.3f}",
            ]
        )
    return rows


MEAN_COLUMNS = ("level (worlds)", "fill", "L_ref m", *METRIC_COLUMNS)


def text_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(header)]
    lines = ["  ".join(h.ljust(w) for h, w in zip(header, widths, strict=True))]
    lines += ["  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)) for r in rows]
    return "\n".join(line.rstrip() for line in lines)


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


def suite_markdown(worlds: Sequence[GeneratedWorld], command: str) -> str:
    from pnav.navbench.generator import LEVELS

    used = dict.fromkeys(w.level for w in worlds)
    level_rows = [
        [
            level,
            f"{LEVELS[level].fill_probability}",
            str(LEVELS[level].smoothing_iterations),
            str(LEVELS[level].fill_threshold),
            str(LEVELS[level].clear_threshold),
        ]
        for level in used
    ]
    return (
        "\n\n".join(
            [
                "# Benchmark worlds (BARN-style)",
                "Generated, not drawn by hand: do not edit these files; generate them again. The "
                "method, the levels, the metrics and the world file fields are in "
                "`docs/NAVBENCH.md`. Written by:",
                f"```sh\n{command}\n```",
                "`python -m pnav.navbench.worlds_cli generate ...` takes the same options. The "
                "output does not depend on the machine: the same command writes the same bytes.",
                "## Levels",
                markdown_table(
                    ("level", "fill probability", "smoothing steps", "fill if >=", "clear if <="),
                    level_rows,
                ),
                "## Means per level",
                markdown_table(MEAN_COLUMNS, level_means(worlds)),
                "## Worlds",
                "`fill`: occupied share of the field; `tries`: fields drawn until one had a path; "
                "`L_ref`: reference path length; `OT`: optimal time at 0.22 m/s; `limit`: the "
                "suggested time limit (8 OT, rounded up to 10 s); then the difficulty metrics.",
                markdown_table((*COLUMNS, *METRIC_COLUMNS), table_rows(worlds)),
            ]
        )
        + "\n"
    )


def world_header(command: str) -> str:
    """The comment on top of every world file of a suite written by ``command``."""
    return (
        f"BARN-style benchmark world, written by `{command}`.\n"
        "Generated: do not edit (the reference path is computed for this map). "
        "Fields: docs/NAVBENCH.md."
    )


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
    from pnav.navbench.generator import LEVELS, generate_suite
    from pnav.navbench.render import draw_generated, write_world_png
    from pnav.navbench.worldfile import write_world

    if getattr(args, "protocol", "default") == "barn":
        return generate_barn(args)
    if getattr(args, "protocol", "default") == "dynabarn":
        return generate_dynabarn(args)
    if getattr(args, "model", None):
        raise UsageError(
            "--model needs --protocol barn or dynabarn (the default protocol's worlds are for "
            "the Burger)"
        )
    levels = checked_levels(args, list(LEVELS))
    command = command_line(args)
    worlds = generate_suite(levels, args.count, args.seed)
    out: Path = args.out
    header = world_header(command)
    for world in worlds:
        write_world(world, out, header=header)
        if args.png:
            write_world_png(out / "preview" / f"{world.name}.png", draw_generated(world))
    (out / "SUITE.md").write_text(suite_markdown(worlds, command))
    print(text_table((*COLUMNS, *METRIC_COLUMNS), table_rows(worlds)))
    print()
    print(text_table(MEAN_COLUMNS, level_means(worlds)))
    return finish(out, [w.name for w in worlds])


def generate_barn(args: argparse.Namespace) -> int:
    """``--protocol barn``: the same files, the obstacles as world obstacles (barnfile.py)."""
    from pnav.navbench import barnfile
    from pnav.navbench.barn import LEVELS, generate_barn_suite
    from pnav.navbench.robots import resolve_model

    levels = checked_levels(args, list(LEVELS))
    robot = resolve_model(args.model or BARN_DEFAULT_MODEL)
    command = command_line(args)
    worlds = generate_barn_suite(levels, args.count, args.seed, robot)
    out: Path = args.out
    header = (
        f"BARN-protocol benchmark world, written by `{command}`.\n"
        "Generated: do not edit (the reference path is computed for this map and these "
        "obstacles). Fields: docs/NAVBENCH.md."
    )
    for world in worlds:
        barnfile.write_barn_world(world, out, header=header)
        if args.png:
            barnfile.write_preview(out / "preview" / f"{world.name}.png", world)
    (out / "SUITE.md").write_text(barnfile.barn_suite_markdown(worlds, command))
    print(text_table((*barnfile.COLUMNS, *METRIC_COLUMNS), barnfile.table_rows(worlds)))
    print()
    print(text_table(MEAN_COLUMNS, level_means(worlds)))
    return finish(out, [w.name for w in worlds])


def generate_dynabarn(args: argparse.Namespace) -> int:
    """``--protocol dynabarn``: BARN's corridor crossed by movers (dynabarnfile.py)."""
    from pnav.navbench import dynabarnfile
    from pnav.navbench.dynabarn import LEVELS, generate_dynabarn_suite
    from pnav.navbench.robots import resolve_model

    levels = checked_levels(args, list(LEVELS))
    robot = resolve_model(args.model or BARN_DEFAULT_MODEL)
    command = command_line(args)
    worlds = generate_dynabarn_suite(levels, args.count, args.seed, robot)
    out: Path = args.out
    header = (
        f"Dynamic BARN-protocol benchmark world, written by `{command}`.\n"
        "Generated: do not edit (the movers are drawn from the seed). Fields: docs/NAVBENCH.md."
    )
    for world in worlds:
        dynabarnfile.write_dynabarn_world(world, out, header=header)
        if args.png:
            dynabarnfile.write_preview(out / "preview" / f"{world.name}.png", world)
    (out / "SUITE.md").write_text(dynabarnfile.dynabarn_suite_markdown(worlds, command))
    print(text_table(dynabarnfile.COLUMNS, dynabarnfile.table_rows(worlds)))
    return finish(out, [w.name for w in worlds])


def finish(out: Path, written_names: Sequence[str]) -> int:
    """Say what was written, and warn of other benchmark worlds in the folder."""
    from pnav.navbench.worldfile import is_benchmark_world

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
    """``python -m pnav.navbench.worlds_cli generate ...``: the same, without ``pnav``."""
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
