"""proactive-nav's tooling: the command line (cli), running the stack (run), the benchmarks
(bench), the in-process reference (monolith), the recorder (record), learning (learn) and
the ROS 2 side for people (ros2)."""
