"""``python -m services.dashboard``: serve the dashboard until SIGINT/SIGTERM."""

from __future__ import annotations

import sys

from services.dashboard.service import main

if __name__ == "__main__":
    sys.exit(main())
