"""slam_lcd.outputs: the files a run writes (trajectories, loops.csv judged against ground truth, reports, plots), as one set.

May import: every stage (eval, backend, io writers), config, types; nothing imports it but the runner and the CLI.
"""
