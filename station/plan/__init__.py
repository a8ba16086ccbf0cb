"""The plan and path safety: the procedure as small steps checked before anything
moves, where the axes may pass during a move, the gauges mounted on a leg, and the
plunger guard's prediction (its runtime monitor is the engine's)."""
