"""The controller's plug-in interface (as nav2_core is Nav2's): what a controller scenario
is written against, shipped or not.

- :mod:`common.controller_core.scenario`: ``ControllerScenario`` (the base target rule),
  ``Command`` (what ``decide`` returns), the ``Host`` Protocol the rules see, and the
  entry-point group the controller loads them from;
- :mod:`common.controller_core.params`: ``number``, a strategy param with its default.

A plug-in package (pnav_local, a team's own) imports these and never ``services``: the
controller service implements ``Host`` (services/controller/store.py) and runs whatever
the entry points name (docs/CONTROLLER.md, "Adding a controller scenario").
"""
