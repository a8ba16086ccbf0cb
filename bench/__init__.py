"""Benchmarks: scripts that print the figures BENCHMARKS.md quotes (run them as
``python bench/NAME.py``); a package only so that the layering check sees them."""
