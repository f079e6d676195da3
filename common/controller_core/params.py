"""Scenario parameters from the strategy's ``params`` (jsonb), with documented defaults.

A strategy is data (a row of the ``strategy`` table): anyone may INSERT one with odd params.
A missing key takes its default; a value that is not a number in range is logged once and
also takes its default, so a typo in a strategy never stops a safety scenario.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping
from typing import Any

from common import log

logger = logging.getLogger("pnav.controller")

_warned: set[tuple[str, str]] = set()


def number(
    params: Mapping[str, Any],
    key: str,
    default: float,
    *,
    low: float = 0.0,
    high: float = math.inf,
) -> float:
    """``params[key]`` as a float in ``[low, high]``, else ``default``."""
    raw = params.get(key)
    if raw is None:
        return default
    value = math.nan
    if not isinstance(raw, bool):
        try:
            value = float(raw)
        except (TypeError, ValueError):
            pass
    if low <= value <= high:  # false for nan
        return value
    if (key, repr(raw)) not in _warned:
        _warned.add((key, repr(raw)))
        log.event(
            logger,
            logging.WARNING,
            "strategy parameter out of range; using the default",
            key=key,
            value=repr(raw),
            default=default,
            low=low,
            high=high,
        )
    return default
