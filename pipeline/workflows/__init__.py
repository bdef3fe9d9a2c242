"""Whole jobs, from inputs to files on disk: what a `guide` command or a DVC stage runs."""
