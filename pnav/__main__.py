from __future__ import annotations

import sys

from pnav.cli import main

sys.exit(main())
