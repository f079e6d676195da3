"""The ``pnav`` command line: run the stack, drive it, and measure it."""
