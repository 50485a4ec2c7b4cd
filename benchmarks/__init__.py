"""Benchmarks (``make bench``): speed and memory figures with their targets, never timed unit tests."""
