"""avoid_right: an obstacle in the front-left sector -> turn right (see avoid.py)."""

from __future__ import annotations

from services.controller.avoid import RIGHT, AvoidScenario


class AvoidRight(AvoidScenario):
    scenario = "avoid_right"
    side = RIGHT
