"""avoid_left: an obstacle in the front-right sector -> turn left (see avoid.py)."""

from __future__ import annotations

from services.controller.avoid import LEFT, AvoidScenario


class AvoidLeft(AvoidScenario):
    scenario = "avoid_left"
    side = LEFT
