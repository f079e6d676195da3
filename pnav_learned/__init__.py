"""Learned scenarios: recommenders trained on the stack's own records (docs/LEARNING.md)."""
