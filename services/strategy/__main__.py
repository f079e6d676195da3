"""``python -m services.strategy``: run the strategy service until SIGINT/SIGTERM."""

from __future__ import annotations

import sys

from services.strategy.service import StrategyService

if __name__ == "__main__":
    sys.exit(StrategyService.main())
