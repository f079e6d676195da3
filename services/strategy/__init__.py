"""The strategy service: user and system commands -> each robot's active_strategy.

Run it with ``python -m services.strategy``; docs/STRATEGY.md describes it.
"""
