"""slam_lcd.cloud: the map as a point cloud: per-keyframe sensor points, a voxel grid, sharpness figures, PLY/PCD files.
May import: vision and the base modules (numpy, scipy, cv2, plyfile); never io, outputs, sim or cli.

Why its own package: the cloud is an output of a run (``map.ply``, ``map_odometry.ply``) and of
``slam-lcd export-map``, measured the same way in both; the library pieces take arrays and
:class:`~slam_lcd.types.CameraModel`, so a plugin user can build a map from their own poses.
"""
from .builder import MapCloudBuilder
from .config import MapCloudConfig
from .files import read_cloud, write_cloud
from .sensor_points import SensorPoints, depth_points, stereo_points
from .sharpness import sharpness
from .truth import surface_distances
from .voxel_grid import Cloud, VoxelGrid

__all__ = ["Cloud", "MapCloudBuilder", "MapCloudConfig", "SensorPoints", "VoxelGrid",
           "depth_points", "read_cloud", "sharpness", "stereo_points", "surface_distances", "write_cloud"]
