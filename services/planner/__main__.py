"""``python -m services.planner``: run the planner service until SIGINT/SIGTERM."""

from __future__ import annotations

import sys

from services.planner.service import PlannerService

if __name__ == "__main__":
    sys.exit(PlannerService.main())
