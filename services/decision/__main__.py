"""``python -m services.decision``: run the decision service until SIGINT/SIGTERM."""

from __future__ import annotations

import sys

from services.decision.service import DecisionService

if __name__ == "__main__":
    sys.exit(DecisionService.main())
