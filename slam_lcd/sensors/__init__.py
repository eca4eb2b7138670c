"""slam_lcd.sensors: a log turned into typed sources: topic choice, decoding, camera mounting, the VO pass as odometry,
frames, trajectories.
May import: io, frontend (the VO), vision and the base modules; the runner, the CLI and tests import it, no stage does.
"""
