"""``python -m tests.unit.prestart_probe ARGS``: prints what it runs with (the prestart
tests): PROBE from its environment, its arguments, and the module's name."""

from __future__ import annotations

import json
import os
import sys

IMPORTED_WITH = os.environ.get("PROBE")  # what the environment held at import time

if __name__ == "__main__":
    print(json.dumps({"probe": os.environ.get("PROBE"), "argv": sys.argv[1:]}), flush=True)
    sys.exit(3)
