"""Running a scene: the compiled system, the initial state, segments between discontinuities,
output rows, the open loop, the closed loop with its controller, the fused loop and batches.
:func:`simulate` lives here."""
