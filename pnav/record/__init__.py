"""Recording a mission as MCAP with Foxglove's well-known schemas (docs/RECORDING.md).

- ``topics``   contract rows -> Foxglove messages, and the topic and schema of each
- ``ros2``     ``--encoding ros2``: the robot's topics as ROS 2 messages (ros2msg, CDR)
- ``source``   the recorder's SQL: new rows of each recorded table
- ``recorder`` the process: follows notifications, reads the rows, writes the MCAP
- ``info``     ``pnav record info FILE``: what a recording holds

The recorder is one more foreign client of the contract: it reads tables after their change
notifications and never imports a service. ``pnav up --record FILE`` and ``pnav demo --record
FILE`` run it as a supervised process (``python -m pnav.record FILE``).
"""

from __future__ import annotations

# --encoding: Foxglove's well-known schemas (the default), or ROS 2's (ros2msg schemas, CDR)
ENCODINGS = ("foxglove", "ros2")
