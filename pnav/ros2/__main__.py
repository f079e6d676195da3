"""``python -m pnav.ros2``: RViz's 2D Goal Pose in and each robot's plan out (rviz.py), and
Nav2's NavigateToPose and NavigateThroughPoses actions served per robot (nav2actions.py).

Started by ``pnav up --robot-link ros2`` (and ``pnav demo``) as a supervised process acting
for people (``pnav_user``, the Zenoh user ``user``), with the robot link's variables
(PNAV_ROS_DOMAIN_ID, PNAV_ROS2_CONNECT, PNAV_ROS2_LINK_FILE: common/robotlink.py).
"""

from __future__ import annotations

import asyncio
import contextlib
import sys

from common.bus import open_session
from common.config import ServiceConfig
from common.robotlink import RobotLinkSettings
from common.runtime import Runtime, run_service
from pnav.ros2.rviz import RvizLink

SERVICE = "rviz"


async def serve(config: ServiceConfig, stop: asyncio.Event) -> None:
    settings = RobotLinkSettings.from_env()
    runtime = await Runtime.open(config)
    try:
        session = await asyncio.to_thread(open_session, settings.session_settings(config.zenoh))
        try:
            await RvizLink(runtime, settings, session).run(stop)
        finally:
            with contextlib.suppress(Exception):
                session.close()
    finally:
        await runtime.close()


def main(argv: list[str] | None = None) -> int:
    return run_service(SERVICE, serve, argv)


if __name__ == "__main__":
    sys.exit(main())
