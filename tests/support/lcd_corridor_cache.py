"""Features of the RTAB-Map corridor frames, extracted once per test process (shared by test_lcd_* files).

They also go through the project's on-disk feature cache (``$SLAM_LCD_CACHE_DIR`` or
``~/.cache/slam-lcd``; keyed by the folder's files, the extractor settings and the weights'
sha256), so a re-run of the suite does not run SuperPoint on the 84 frames again.
"""
from __future__ import annotations

import functools
from pathlib import Path


@functools.cache
def corridor_features(folder: str, kind: str, weights: str | None) -> tuple:
    """Features of frames 1..84, read exactly as ``slam-lcd eval-lcd`` reads them (same cache entries)."""
    import tempfile

    from filelock import FileLock

    from slam_lcd.features import FeatureCache, FeaturesConfig, load_extractor
    from slam_lcd.io.image_folder import folder_frames

    ex = load_extractor(FeaturesConfig(kind=kind), weights=weights, device="cpu")
    cache = FeatureCache(ex)
    names, _, frames = folder_frames(folder, exclude=[Path(folder) / "samples_GT.bmp"])
    assert names == [f"{i}.jpg" for i in range(1, 85)]
    # one extracting process at a time (pytest-xdist's workers): with a cold cache the second waits and
    # then reads the first one's cache entries instead of running SuperPoint on the same frames again
    with FileLock(str(Path(tempfile.gettempdir()) / f"slam-lcd-tests-corridor-{kind}.lock")):
        return tuple(cache.extract(Path(folder), "images", fr.stamp, fr.image) for fr in frames)  # index k: frame k+1
