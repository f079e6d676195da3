"""Navigation benchmark: BARN-style generated worlds, run metrics (SPL, BARN score), pictures.

Modules: ``automaton`` (the cellular automaton), ``search`` (inflation, A*, reference path),
``difficulty`` (BARN's difficulty metrics), ``generator`` (levels, layout, a world from a
seed), ``worldfile`` (world files and their ``benchmark:`` section), ``metrics`` (outcome,
SPL, score, summaries), ``png`` and ``render`` (pictures), ``worlds_cli`` (``pnav worlds``).
See docs/NAVBENCH.md.
"""
