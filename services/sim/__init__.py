"""The simulator service: pybullet worlds from ROS map_server maps, TurtleBot3 Burger-class
robots, and their sensors on Zenoh (CONTRACT.md). Run it with ``python -m services.sim``;
docs/SIM.md tells how.

Modules, one concept each:

- mapserver  ROS map_server YAML + PGM -> occupancy grid (and a PGM writer)
- world      world files: map, robots, charging stations, obstacles; the world message
- robot      the diff-drive model, its limits and kinematics
- lidar      beam geometry and noisy ranges
- battery    the drain and charge model
- clock      sim-time schedules, wall-clock pacing, --rate
- physics    the pybullet scene: bodies, contact tests
- outline    a world's walls and obstacles as a 2-D lidar sees them
- fleetcast  every scanning robot's lidar, cast together in closed form
- messages   the contract payloads the sim publishes, and cmd_vel parsing
- sim        the simulation loop proper (no Zenoh, no wall time)
- node       the Zenoh side: publishers, cmd_vel, world queryable, the paced loop
- bench      sim seconds per wall second, flat out
"""
