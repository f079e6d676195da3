"""``pnav learn register FILE [--name N] [--version V]``: a people's row of the ``model``
table for a model file (docs/LEARNING.md, *Models as data*), notified so that the
controllers read the register again at once.

The file is checked first, as a learned scenario would load it (learned_drive's or
foresight's kind): a file no scenario could run is refused at the door, and the version
given must be the file's own (it names the weights).
"""

from __future__ import annotations

from pathlib import Path

import asyncpg

from common.contract.models import RegisteredModel, register_model
from common.errors import ContractError, UsageError
from pnav_learned.errors import ModelRefused
from pnav_learned.foresight import KIND as FORESIGHT
from pnav_learned.model import DRIVE, Model, load


def check(file: Path) -> Model:
    """The model in ``file``, as one of the learned scenarios would run it."""
    reasons = []
    for kind in (DRIVE, FORESIGHT):
        try:
            return load(file, None, kind)
        except ModelRefused as exc:
            reasons.append(f"as {kind.scenario}'s: {exc}")
    raise UsageError(f"FILE {file}: not a model a learned scenario can run ({'; '.join(reasons)})")


def row_for(file: Path, name: str | None, version: str | None) -> RegisteredModel:
    """The row to register for ``file``: refused at the door if no learned scenario could
    run it, or ``version`` is not the file's."""
    model = check(file)
    if version is not None and version != model.version:
        raise UsageError(f"--version {version!r}: the file's version is {model.version!r}")
    name = name or model.name
    if not name:
        raise UsageError("--name: the file names no model; give one")
    return RegisteredModel(name, model.version, str(file.resolve()), model.metrics)


async def register(row: RegisteredModel, description: str = "") -> int:
    """Write ``row`` (notified); a (name, version) registered already is refused."""
    from pnav.cli import stack_commands

    rt = await stack_commands.open_runtime()
    try:
        with stack_commands.refusal_as_contract_error():
            try:
                await register_model(rt.database, row, description)
            except asyncpg.UniqueViolationError:
                raise ContractError(
                    f"model {row.name!r} version {row.version!r} is registered already"
                ) from None
    finally:
        await rt.close()
    print(f"model {row.name} version {row.version} registered: {row.path}")
    return 0
