"""The register of learned models (the ``model`` table, CONTRACT.md *model*): rows people
write (``pnav learn register``) and learned scenarios read through their service's store, so
that a strategy's params name a registered version and switching models is an UPDATE.

A row says where a model file is and what it was measured to do; the file itself is still
checked when a scenario loads it (pnav_learned.model): a row is a claim, not a proof.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from common.contract import keys
from common.contract.records import Executor

READ_SQL = "SELECT name, version, path, metrics, created_at FROM model ORDER BY name, created_at"
INSERT_SQL = (
    "INSERT INTO model (name, version, path, metrics, description)"
    " VALUES ($1, $2, $3, $4::jsonb, $5)"
)


@dataclass(frozen=True)
class RegisteredModel:
    """One row of the ``model`` table."""

    name: str
    version: str
    path: str
    metrics: Mapping[str, Any] = field(default_factory=dict)


def _metrics(raw: Any) -> dict[str, Any]:
    value = json.loads(raw) if isinstance(raw, str) else raw
    return dict(value) if isinstance(value, dict) else {}


def of_row(row: Mapping[str, Any]) -> RegisteredModel:
    return RegisteredModel(
        str(row["name"]), str(row["version"]), str(row["path"]), _metrics(row.get("metrics"))
    )


async def read_models(db: Executor) -> list[RegisteredModel]:
    """Every registered model, oldest first within a name."""
    return [of_row(r) for r in await db.fetch(READ_SQL)]


def pick(
    models: Iterable[RegisteredModel], name: str, version: str | None
) -> RegisteredModel | None:
    """The row (name, version); with no version, the newest registered under ``name``
    (``models`` in register order, as :func:`read_models` gives them)."""
    found = None
    for m in models:
        if m.name == name and (version is None or m.version == version):
            found = m
    return found


async def register_model(db: Any, model: RegisteredModel, description: str = "") -> None:
    """Insert ``model`` and notify ``pnav/db/model/_`` (``db``: a common.db.Database, whose
    connections encode jsonb from Python values). The database refuses a (name, version)
    already registered (UniqueViolationError)."""
    await db.write(
        keys.MODEL,
        None,
        INSERT_SQL,
        model.name,
        model.version,
        model.path,
        dict(model.metrics),
        description,
    )
