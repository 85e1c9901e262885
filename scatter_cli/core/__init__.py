"""Machinery that knows no mesh: the compiled kernels' registry and thread count, hashing
and seeding, signals, exit codes and standard output, the progress line."""
