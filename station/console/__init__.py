"""The operator: prompts, the live progress bar, and the virtual operator of a
simulated run."""
