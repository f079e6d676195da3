"""Benchmarks: commands that print figures (and JSON), never timed tests."""
