"""Writers of run outputs (they observe a simulation; the core never imports them)."""
