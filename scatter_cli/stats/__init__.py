"""Statistics with no knowledge of a file or a run: the chi-square harness, the exact
surface measures and equal-area regions that ``scatter check`` and the uniformity tests use."""
