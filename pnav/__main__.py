from __future__ import annotations

import sys

from pnav.cli.program import main

sys.exit(main())
