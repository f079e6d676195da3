"""``pnav learn``: datasets from the stack's records, and models trained on them
(docs/LEARNING.md)."""
