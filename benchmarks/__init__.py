"""Benchmarks: commands that measure speed, memory or robustness on the machine they run on.

Each is run by hand (``python -m benchmarks.NAME --help``) and prints its figures, which the
results log (``docs/results-log.md``) keeps with their date and machine. None is part of the
workflow or of the test suite: the workflow's own timed studies live in :mod:`studies`, and the
pieces a benchmark measures are tested where they live. This package sits above every layer and
nothing imports it.
"""
