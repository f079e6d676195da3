"""Local controllers for proactive-nav: scenarios that drive a robot along the planner's path
at the robot's own speed (docs/CONTROLLER.md, "dwa"). Found by the controller through the
``pnav.controller.scenarios`` entry points; nothing of the controller lists them."""
