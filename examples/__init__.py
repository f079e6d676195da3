"""Examples that use proactive-nav only through its contract (common/contract/CONTRACT.md).

Nothing under ``examples/`` imports ``common`` or ``services``: each example is what a team
writing a service of its own, in any language, would write. They are run from the
repository root (``python -m examples.<name>``) and are not part of the installed package.
"""
