"""The controller service: a Proactive Engine whose meta-controller runs, per robot, the
controller scenarios its strategy names (avoid_left, avoid_right, safety_stop, ...).

Each controller scenario reads the newest laser scan (and, if it needs it, odometry) and writes
velocity recommendations with its own priority; the decision service arbitrates. See
docs/CONTROLLER.md.
"""
