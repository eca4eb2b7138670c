"""What a keyframe made by a user's own front end must hold for the loop detector (docs/plugin.md).

Minimal keyframe: ``Keyframe(id, stamp, T_world_body, image=..., camera=...)`` plus one source
of 3-D points for a metric loop pose: ``depth`` (metric, aligned with the image), or
``right_image`` (rectified, with ``camera.baseline``), or ``landmarks`` (camera-frame point
per keypoint of ``features``). ``id``: any distinct integer (a GTSAM key such as
``Symbol('x', i).key()`` works); ids need not be consecutive or ordered, the detector
orders keyframes by arrival and excludes recent ones by ``stamp``. Without a 3-D source
loops are still verified but carry no metric pose (``lcd.require_pose`` then rejects
them). The checks here turn silent misuse (landmarks that cannot be matched to keypoints)
into a typed error naming the keyframe.
"""
from __future__ import annotations

import numbers

import numpy as np

from ..errors import InputError
from ..types import Keyframe


def check_user_keyframe(kf: Keyframe) -> None:
    """Raise :class:`~slam_lcd.errors.InputError` for a keyframe the detector cannot use as given."""
    if isinstance(kf.id, bool) or not isinstance(kf.id, numbers.Integral):
        raise InputError(f"keyframe id {kf.id!r} is not an integer (use e.g. the GTSAM key of its pose)")
    if kf.features is None and kf.image is None:
        raise InputError(f"keyframe {kf.id} has neither features nor an image")
    if kf.landmarks is not None:
        lm = np.asarray(kf.landmarks)
        if kf.features is None:
            raise InputError(f"keyframe {kf.id}: landmarks are per keypoint, so the keyframe needs its features too")
        if lm.ndim != 2 or lm.shape != (len(kf.features), 3):
            raise InputError(f"keyframe {kf.id}: landmarks must be ({len(kf.features)}, 3), one camera-frame point "
                             f"per keypoint (NaN where unknown), got {lm.shape}")
