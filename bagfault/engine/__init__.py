"""Engine: the run loop, bag-time scheduler, router, time-ordered merge, per-fault random streams."""
