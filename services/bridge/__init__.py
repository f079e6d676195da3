"""The bridge service: sim sensors -> contract tables, command2robot -> the robot's cmd_vel.

Run it with ``python -m services.bridge`` (configuration from ``PNAV_*`` variables, see
``common.config`` and :mod:`services.bridge.settings`); docs/BRIDGE.md describes it.
"""

from services.bridge.bridge import Bridge, main, serve
from services.bridge.settings import BridgeSettings

__all__ = ["Bridge", "BridgeSettings", "main", "serve"]
