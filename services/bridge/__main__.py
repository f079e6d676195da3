"""``python -m services.bridge``: run the bridge until SIGINT/SIGTERM."""

from __future__ import annotations

import sys

from services.bridge.bridge import main

if __name__ == "__main__":
    sys.exit(main())
