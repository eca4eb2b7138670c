"""Which building a world seed builds: the seed ranges, as plain numbers.

Seeds below :data:`OTHER_PLACE_SEED` are the demo building (the seed re-draws textures and
lamp states only), seeds from it to :data:`LOOKALIKE_SEED` another building on the same
corridors, and seeds from :data:`LOOKALIKE_SEED` on the demo building with a look-alike
corridor (:mod:`slam_lcd.sim.building` places each).

Why apart from :mod:`slam_lcd.sim.building`: the session presets (:mod:`slam_lcd.sim.sessions`)
name these seeds, and the command line reads the presets for ``make-demo-log --session``'s
choices and help without loading numpy.
"""
from __future__ import annotations

OTHER_PLACE_SEED = 1000  # world seeds from here to LOOKALIKE_SEED are another building on the same corridors
LOOKALIKE_SEED = 2000  # world seeds from here on are the demo building with a look-alike corridor
