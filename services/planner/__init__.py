"""The planner service: the meta-planner, the planner scenarios (turn_then_move,
move_while_turning), the path planner on the map's occupancy grid, and the battery rules.
See docs/PLANNER.md."""
