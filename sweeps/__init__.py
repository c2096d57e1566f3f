"""Command line, experiments and sweeps of the ShaCC evaluator."""
