"""Benchmarks: speed and statistical studies that print figures. Not run in CI (see README)."""
