"""Which model a learned scenario runs: the strategy's params name it, the ``model`` table
says where its file is (common.contract.models), the file is checked when loaded
(pnav_learned.model).

Params, per scenario (``learned_model`` / ``learned_model_version`` for learned_drive,
``foresight_model`` / ``foresight_model_version`` for foresight):

- the name of a registered model, with a version: that row of the ``model`` table; without
  one: the newest row registered under the name. The file the row names must have that
  version. Switching models at run time is an UPDATE of the strategy's params (or a new row
  under the name), seen within the controller store's re-read of the table (2 s, or at once
  when notified);
- otherwise, as before the register existed, a model file (a relative path is taken from
  ``PNAV_MODEL_DIR``, else the controller's working directory), with the version it must
  have, if given.

A model that cannot be used is a reason (a string), never an exception: the scenario stands
down and says why, once, in the log; the strategy's other scenarios drive.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from common import log
from common.controller_core.scenario import Host
from pnav_learned.errors import ModelRefused
from pnav_learned.model import Kinds, Model, load, scenario_of

logger = logging.getLogger("pnav.controller")


@dataclass(frozen=True)
class Found:
    """A model ready to run, and how the strategy named it (for the recommendations' why)."""

    model: Model
    registered: bool  # named through the model table (else a file named in the params)

    @property
    def label(self) -> str:
        m = self.model
        return f"model {m.name} version {m.version}" + (" (registered)" if self.registered else "")


# (kind, path, version, file's mtime) -> the model or why it was refused. Loaded models are
# immutable and shared by every robot's rule (one copy of the weights per file); what a
# robot's rule remembers is in the rule itself.
_cache: dict[tuple[str, str, str | None, float], Model | str] = {}


def model_path(name: str) -> Path:
    p = Path(name)
    return p if p.is_absolute() else Path(os.environ.get("PNAV_MODEL_DIR", ".")) / p


def load_cached(path: Path, version: str | None, kind: Kinds) -> Model | str:
    """The model at ``path`` (cached until the file's modification time changes), or why
    it is refused (logged once per file, version and modification)."""
    try:
        mtime = path.stat().st_mtime
    except OSError:
        mtime = -1.0
    key = (scenario_of(kind), str(path), version, mtime)
    if key not in _cache:
        try:
            _cache[key] = load(path, version, kind)
        except ModelRefused as exc:
            _cache[key] = f"model refused: {exc}"
        found = _cache[key]
        log.event(
            logger,
            logging.WARNING if isinstance(found, str) else logging.INFO,
            f"{scenario_of(kind)} model",
            path=str(path),
            outcome=found if isinstance(found, str) else f"loaded version {found.version}",
        )
    return _cache[key]


def named(params: Mapping[str, Any], prefix: str) -> tuple[str | None, str | None]:
    """(model, version) as the params name them under ``PREFIX_model``,
    ``PREFIX_model_version`` (None: not named, or not a string)."""
    name, version = params.get(f"{prefix}_model"), params.get(f"{prefix}_model_version")
    return (
        name if isinstance(name, str) and name else None,
        version if isinstance(version, str) and version else None,
    )


async def resolve(host: Host, params: Mapping[str, Any], prefix: str, kind: Kinds) -> Found | str:
    """The model the params name (see the module's docstring), or why there is none."""
    name, version = named(params, prefix)
    if name is None:
        return f"no model: the strategy's params name none ({prefix}_model)"
    row = await host.registered_model(name, version)
    if row is not None:
        found = load_cached(model_path(row.path), row.version, kind)
        return found if isinstance(found, str) else Found(found, True)
    found = load_cached(model_path(name), version, kind)
    if isinstance(found, str) and version is not None:
        found += f" (and no model {name!r} version {version!r} is registered)"
    return found if isinstance(found, str) else Found(found, False)
