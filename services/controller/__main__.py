"""``python -m services.controller``: run the controller service."""

from __future__ import annotations

import sys

from services.controller.service import ControllerService

if __name__ == "__main__":
    sys.exit(ControllerService.main())
