"""Run metrics: observers that watch a simulation step by step and report numbers for the
summary (capture time, coverage, ...). The core never imports them.

A metric has ``update(sim) -> bool`` (True asks the run to end, e.g. on capture) and
``result() -> dict`` (JSON-ready, merged into summary.json under ``metrics``).
"""
