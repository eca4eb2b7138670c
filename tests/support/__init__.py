"""Test harnesses: scenarios and solvers the tests (and tools/bench_backend.py) drive the library with."""
