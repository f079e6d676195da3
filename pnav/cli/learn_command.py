"""``pnav learn dataset``, ``pnav learn train`` and ``pnav learn register`` (docs/LEARNING.md).
Heavy imports (pyarrow, scikit-learn) wait until a command runs: pnav's parser is built on
every command."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from common.errors import UsageError


def add_learn_parser(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    learn = commands.add_parser("learn", help="datasets from the records, and learned models")
    steps = learn.add_subparsers(dest="learn", metavar="STEP", required=True)
    data = steps.add_parser(
        "dataset", help="one example per decision of a database, to Parquet (docs/LEARNING.md)"
    )
    where = data.add_mutually_exclusive_group(required=True)
    where.add_argument("--dsn", metavar="URL", help="a live stack's database")
    where.add_argument(
        "--db-dir", type=Path, metavar="DIR", help="a kept database (pnav bench nav --keep-db)"
    )
    data.add_argument("--out", type=Path, required=True, metavar="FILE.parquet")
    data.add_argument(
        "--horizon", type=float, default=3.0, metavar="S", help="outcome horizon, sim s (3)"
    )
    data.add_argument(
        "--label",
        choices=("dwa",),
        help="targets: what this controller would have commanded in each recorded state"
        " (DAgger), not what the stack decided; with dwa, also its cell of dwa's lattice and"
        " the cells that pass learned_drive's check (train --target lattice)",
    )
    data.add_argument(
        "--label-strategy",
        metavar="CODE",
        help="the strategy row whose dwa_* params the label uses (default: the robot's active)",
    )
    train = steps.add_parser("train", help="train a learned scenario's model on datasets")
    train.add_argument(
        "--data", type=Path, required=True, nargs="+", metavar="FILE.parquet", help="one or more"
    )
    train.add_argument("--out", type=Path, required=True, metavar="MODEL.json")
    train.add_argument(
        "--target",
        choices=("drive", "foresight", "lattice"),
        default="drive",
        help=(
            "drive: learned_drive's velocity (default); lattice: learned_drive's classifier"
            " over dwa's lattice (data from --label dwa); foresight: no progress within 3 s"
        ),
    )
    train.add_argument(
        "--test",
        type=Path,
        nargs="+",
        metavar="FILE.parquet",
        help="held-out examples from these files (other worlds) instead of a seeded fifth",
    )
    train.add_argument(
        "--name", help="the model's name (default: learned_drive, or foresight with its target)"
    )
    train.add_argument(
        "--sources", default="", help="only decisions won by these scenarios, e.g. dwa"
    )
    train.add_argument(
        "--hidden", default="32,32", help="hidden layer widths, comma-separated (32,32)"
    )
    train.add_argument("--seed", type=int, default=0)
    register = steps.add_parser(
        "register", help="register a model file in the model table (people's row)"
    )
    register.add_argument("file", type=Path, metavar="MODEL.json")
    register.add_argument("--name", help="the name to register under (default: the file's)")
    register.add_argument("--version", help="the version; must be the file's (default: the file's)")
    register.add_argument("--description", default="", help="for people, one line")


def _hidden(text: str) -> tuple[int, ...]:
    try:
        widths = tuple(int(w) for w in text.split(","))
    except ValueError:
        raise UsageError(f"--hidden {text!r}: comma-separated integers expected") from None
    if not 1 <= len(widths) <= 4 or not all(1 <= w <= 256 for w in widths):
        raise UsageError(f"--hidden {text!r}: 1 to 4 widths, each 1 to 256")
    return widths


async def _dataset(args: argparse.Namespace) -> int:
    import asyncpg

    from pnav.learn import dataset, relabel

    if not args.horizon > 0:
        raise UsageError(f"--horizon {args.horizon}: must be positive")
    if args.label_strategy is not None and args.label is None:
        raise UsageError("--label-strategy: only with --label")
    postgres: Any = None
    dsn = args.dsn
    if args.db_dir is not None:
        if not (args.db_dir / "PG_VERSION").is_file():
            raise UsageError(f"--db-dir {args.db_dir}: not a Postgres data directory")
        from pnav.run.embedded_postgres import EmbeddedPostgres

        # stopped again at the end (the data directory given is never removed)
        postgres = EmbeddedPostgres(args.db_dir)
        postgres.start()
        dsn = postgres.dsn()
    try:
        conn = await asyncpg.connect(dsn)
        try:
            label = None
            if args.label is not None:
                label = await relabel.labeller(conn, args.label, args.label_strategy)
            found = await dataset.read(conn, args.horizon, label)
        finally:
            await conn.close()
    finally:
        if postgres is not None:
            postgres.stop()
    meta = {"pnav.horizon_s": str(args.horizon)}
    if args.label is not None:
        meta["pnav.label"] = args.label
    dataset.to_parquet(found, str(args.out), meta)
    labelled = ""
    if args.label is not None:
        silent = sum(1 for v in found.columns["linear_mps_cmd"] if v != v)  # NaN
        labelled = f", labelled by {args.label} ({silent} where it had nothing to say)"
    print(
        f"{found.examples} examples from {found.decisions} decisions"
        f" ({found.skipped} with no scan, odometry or path){labelled} -> {args.out}"
    )
    return 0


def run_learn(args: argparse.Namespace) -> int:
    if args.learn == "dataset":
        import uvloop

        return uvloop.run(_dataset(args))
    if args.learn == "register":
        import uvloop

        from pnav.learn.register import register, row_for

        row = row_for(args.file, args.name, args.version)
        return uvloop.run(register(row, args.description))
    if args.learn == "train":
        from pnav.learn.train import train

        sources = tuple(s for s in args.sources.split(",") if s)
        default_name = "foresight" if args.target == "foresight" else "learned_drive"
        doc = train(
            args.data,
            args.out,
            name=args.name or default_name,
            hidden=_hidden(args.hidden),
            sources=sources,
            seed=args.seed,
            target=args.target,
            test=args.test,
        )
        summary = {k: doc[k] for k in ("name", "version", "data_sha256", "metrics")}
        json.dump(summary, sys.stdout, indent=1)
        print()
        return 0
    raise AssertionError(f"unhandled learn step {args.learn}")
