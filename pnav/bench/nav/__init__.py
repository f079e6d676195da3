"""Navigation benchmark: BARN-style generated worlds, run metrics (SPL, BARN score), pictures.

Modules: ``automaton`` (the cellular automaton), ``search`` (inflation, A*, reference path),
``difficulty`` (BARN's difficulty metrics), ``generator`` (levels, layout, a world from a
seed), ``worldfile`` (world files and their ``benchmark:`` section), ``scores`` (outcome,
SPL, score, summaries), ``png`` and ``render`` (pictures), ``worlds_cli`` (``pnav worlds``),
``stack_episode`` (one run of the whole stack), ``runner`` (``pnav bench nav``),
``nav_report`` (its tables, JSON and README), ``run_diff`` (``--compare``).
See docs/NAVBENCH.md.
"""
