"""slam_lcd.cloud: the map as a point cloud: per-keyframe sensor points, a voxel grid, sharpness figures, PLY/PCD files.
May import: vision and the base modules (numpy, scipy, cv2, plyfile); never io, outputs, sim or cli.

Why its own package: the cloud is an output of a run (``map.ply``, ``map_odometry.ply``) and of
``slam-lcd export-map``, measured the same way in both; the library pieces take arrays and
:class:`~slam_lcd.types.CameraModel`, so a plugin user can build a map from their own poses.

Names are imported on first use (PEP 562): the configuration imports this package, and a
command that needs none of these must not pay numpy, scipy or OpenCV for them.
"""
from __future__ import annotations

from ..runtime.lazy_names import lazy_getattr
from .config import MapCloudConfig

_LAZY = {
    "MapCloudBuilder": ".builder",
    "read_cloud": ".files",
    "write_cloud": ".files",
    "SensorPoints": ".sensor_points",
    "depth_points": ".sensor_points",
    "stereo_points": ".sensor_points",
    "sharpness": ".sharpness",
    "surface_distances": ".truth",
    "Cloud": ".voxel_grid",
    "VoxelGrid": ".voxel_grid",
}

__all__ = ["MapCloudConfig", *_LAZY]

__getattr__ = lazy_getattr(__name__, _LAZY, globals())
