"""What a run writes: CSV rows (:mod:`.csv`) and rerun recordings (:mod:`.rerun`).

Kept free of imports: the command line starts the recording child (:mod:`.rerun.child`) before
casadi, scipy and pydantic are imported."""
