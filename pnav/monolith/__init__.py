"""The navigation logic in one process, without Postgres or Zenoh: the reference the stack's
cost is measured against (docs/MONOLITH.md). ``run_monolith_episode`` is the entry point."""

from __future__ import annotations

from pnav.monolith.monolith_episode import MonolithOutcome, run_monolith_episode

__all__ = ["MonolithOutcome", "run_monolith_episode"]
