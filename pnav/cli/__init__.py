"""The ``pnav`` command line: its parser and the verbs that only parse and dispatch.

- ``program``           the ``pnav`` entry point (``main``) and what each command does
- ``parser``            every command's parser and options
- ``options``           argument types and the options several commands share
- ``stack_commands``    ``pnav goal | strategy | cancel | status | down | env | migrate``
- ``zone_command``      ``pnav zone``
- ``learn_command``     ``pnav learn`` (the work itself is in pnav/learn)
- ``dashboard_options`` where ``pnav up`` and ``pnav demo`` serve the dashboard

Running the stack is pnav/run's, measuring it pnav/bench's.
"""
