"""Studies on top of runs: the cross-formulation check, work-precision and stability."""
