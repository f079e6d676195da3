"""The ROS 2 side that acts for people: RViz's goals in, the planned paths out (rviz.py)."""
