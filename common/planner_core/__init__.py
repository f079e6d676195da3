"""The planner's plug-in interface (as nav2_core is Nav2's): what a move scenario is written
against, shipped or not.

- :mod:`common.planner_core.scenario`: ``MoveScenario`` (the base a move scenario
  subclasses: its ``select``), ``Movement`` (what ``select`` returns), ``RobotInfo`` (the
  robot it sees), ``clamp`` and ``cruise_speed``, and the entry-point group the planner
  loads them from.

A plug-in package imports these and never ``services``: the planner service supplies the
rule around ``select`` (the target, the route, reaching it, the cadence of recommendations:
services/planner/scenario.py) and runs whatever the entry points name (docs/PLANNER.md,
"Adding a move scenario").
"""
