"""Running the stack on one machine: what ``pnav up``, ``pnav demo`` and the benchmarks start.

- ``launcher``            Postgres, the Zenoh router and every service process (``launched``)
- ``process_supervisor``  the service processes: restarted when they crash, stopped cleanly
- ``prestart``            a process started before its environment (``python -m pnav.run.prestart``)
- ``composition``         one process per service, or several in a host process
- ``host``                a host process (``python -m pnav.run.host SERVICE...``)
- ``supervisor_report``   the supervisor's restarts, told to the stack on Zenoh
- ``stackfile``           where a running stack says how to reach it
- ``credentials``         the fleet's passwords (``pnav secrets``)
- ``up``, ``demo``        ``pnav up`` and ``pnav demo``; ``mission`` follows a robot's mission
"""
