"""The run engine: the flow of a calibration (measure, identify, write back, verify,
the closed loop), the sequencer that executes the plan against the devices, the
plunger guard that watches its moves, and the result document it fills."""
