"""Section ``map_cloud`` of the configuration: how the map's point cloud is built and measured."""
from __future__ import annotations

from dataclasses import dataclass

from ..value_range import ranged


@dataclass
class MapCloudConfig:
    """Section `map_cloud`: the map as a point cloud (``map.ply``, ``map_odometry.ply``; docs/map_cloud.md)."""

    # build the clouds, their sharpness figures and top views (needs depth or a stereo pair)
    enabled: bool = True
    # edge of the voxel that merges points (m): one point per occupied voxel (the centroid)
    voxel_m: float = ranged(0.05, "[0.001, inf)")
    # depth range used (m): nearer or farther sensor points are dropped (stereo and depth noise grow as z^2)
    min_depth_m: float = ranged(0.3, "[0, inf)", below="max_depth_m")
    max_depth_m: float = ranged(5.0, "(0, inf)")
    # every this-many-th pixel in both directions is back-projected: pixel_step * max_depth_m / fx <= voxel_m
    # still puts a pixel in every voxel of a wall facing the camera (640x480, fx ~460: 4 at 5 m and 5 cm)
    pixel_step: int = ranged(4, "[1, 64]")
    # a voxel is kept when this many keyframe points fall in it (each keyframe gives at most one per voxel of
    # its own frame): a point seen by one keyframe only is more often a stereo or depth outlier than a surface
    min_keyframes_per_voxel: int = ranged(2, "[1, 1000]")
    # stereo: semi-global matching on the pair scaled down by this (1: full resolution)
    stereo_match_step: int = ranged(2, "[1, 16]")
    # stereo: drop disparities whose 3x3 neighbourhood spreads over more than this many pixels of the matched
    # image (an object's edge: the matching window gives depths between foreground and background; 0: keep)
    stereo_max_jump_px: float = ranged(1.0, "[0, inf)")
    # keyframes waiting for the cloud's own thread, which takes them in while the run goes on (0: taken in
    # the thread that hands them over, the run waiting for each)
    queue_keyframes: int = ranged(4, "[0, 256]")
    # the sharpness figures: neighbours within this radius (m) of a point give its covariance
    metric_radius_m: float = ranged(0.3, "(0, inf)")
    # ... evaluated at this many points drawn evenly (seeded) from the cloud, all points as neighbours
    metric_points: int = ranged(5000, "[1, inf)")
    # a neighbourhood needs this many points for a covariance
    metric_min_neighbours: int = ranged(8, "[4, inf)")
    # the entropy's floor per direction, in voxels: thinner than this is below the map's resolution
    # (docs/map_cloud.md: without it the figure rewards ghosting)
    metric_min_std_voxels: float = ranged(0.2, "[0, 10]")
    # write the cloud into corrected.mcap as sensor_msgs/PointCloud2 on this topic ("" = not written)
    mcap_topic: str = "/slam_lcd/map_cloud"
    # the top-view images: pixels of the longer side
    top_view_px: int = ranged(900, "[100, 8000]")
