"""The decision service: live recommendations -> command2robot and system_command.

Run it with ``python -m services.decision``; docs/DECISION.md describes it.
"""
