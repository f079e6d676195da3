"""Typed access to one mapping of a world file (the world itself, a robot entry, a charging
station, an obstacle), each refusal a WorldError naming the file and the entry:
``world.yaml: robots[0]: 'x' must be a number, got 'left'``."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from common import yamldoc
from common.contract import keys
from common.errors import WorldError


class EntryReader:
    """Typed access to one YAML mapping, with errors that name the file and the entry."""

    def __init__(self, path: Path, doc: Any, where: str) -> None:
        if not isinstance(doc, dict):
            raise WorldError(f"{path}: {where} must be a mapping, got {doc!r}")
        self.path, self.doc, self.where = path, doc, where

    def error(self, problem: str) -> WorldError:
        return WorldError(f"{self.path}: {self.where}: {problem}")

    def only(self, known: tuple[str, ...], hint: str = "") -> None:
        """Refuse a key not in ``known`` (a typo is an error, never silently ignored),
        naming the closest known one; ``hint`` is added after the problem."""
        key = yamldoc.unknown_key(self.doc, known)
        if key is not None:
            raise self.error(yamldoc.unknown_key_problem(key, known) + hint)

    def number(self, key: str, default: float | None = None) -> float:
        if key not in self.doc:
            if default is None:
                raise self.error(f"missing required key '{key}'")
            return default
        value = self.doc[key]
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.error(f"'{key}' must be a number, got {value!r}")
        if not math.isfinite(value):
            raise self.error(f"'{key}' must be finite, got {value!r}")
        return float(value)

    def positive(self, key: str, default: float | None = None) -> float:
        value = self.number(key, default)
        if value <= 0:
            raise self.error(f"'{key}' must be positive, got {value}")
        return value

    def ident(self, key: str, default: str | None = None) -> str:
        value = self.doc.get(key, default)
        if value is None:
            raise self.error(f"missing required key '{key}'")
        value = str(value)
        if not keys.valid_id(value):
            raise self.error(f"'{key}' {value!r} must match [A-Za-z0-9_-]+")
        return value
