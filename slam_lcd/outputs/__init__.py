"""slam_lcd.outputs: the files a run writes, as one set.

Trajectories, loops.csv judged against ground truth, reports, plots.
May import: the stages (eval, backend), io writers, config and the base modules; only the runner and the CLI import it.
"""
