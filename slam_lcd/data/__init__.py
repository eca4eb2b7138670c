"""Runtime data shipped inside the package (configuration presets in ``configs/``).

Why a package and not a top-level folder: a wheel installs only what is inside the package,
so data read at run time must live here and be found through :mod:`importlib.resources`
(never through a path relative to the source checkout).
"""
