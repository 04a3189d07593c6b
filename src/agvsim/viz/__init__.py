"""Plots and viewers (they observe a simulation; the core never imports them)."""
