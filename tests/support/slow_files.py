"""The test files handed to the workers first (tests/conftest.py orders the collection by it)."""

# pytest-xdist (``--dist loadfile --no-loadscope-reorder``) hands whole files to the two workers in
# collection order. The files that take 30 s or more (measured on the 2-core budget machine, slowest
# first) are handed out first, so that the last files are short ones and both workers finish together.
SLOW_FILES = (
    "batch/test_batch.py", "e2e/test_readme.py", "cli/test_signals.py", "map/test_map_faults.py",
    "map/test_map_lookalike.py", "run/test_pipeline_overlap.py", "eval/test_ate_evo_flags.py",
    "map/test_map_sessions.py", "viewer/test_viewer.py", "map/test_map_cli_rules.py", "run/test_pipeline_demo.py",
    "lcd/test_lcd_symmetry.py", "map/test_map_lifelong.py", "features/test_features_superpoint.py",
    "cli/test_bad_input.py",
)
