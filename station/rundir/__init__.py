"""The run directory: the journal (every reading fsynced before the machine moves
on) and what it says, folded once (state), what a run directory holds, and the lock
that keeps one station per machine."""
