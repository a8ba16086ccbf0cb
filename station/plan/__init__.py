"""The plan and path safety: the procedure as small steps checked before anything
moves, where the axes may pass during a move, and the plunger guard."""
