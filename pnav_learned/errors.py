"""Errors of the learned scenarios."""

from __future__ import annotations

from common.errors import PnavError


class ModelRefused(PnavError):
    """A model file that cannot be used; the message says why."""
