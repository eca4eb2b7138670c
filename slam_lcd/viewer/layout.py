"""The first view of a recording (a Rerun blueprint): 3-D view, keyframe image, ATE over time, loop table.

Why set by the project: Rerun's own heuristic puts every entity in a view of its own kind and
splits the screen evenly; a SLAM run is read from the 3-D view first, with the loop table and
the error over time beside it, so those get the space.
"""
from __future__ import annotations

from . import require_rerun

IMAGE_ORIGIN = "world/live/camera"  # the keyframe images a live run logs (`view` of a run folder: record's)


def blueprint(*, images: bool, ate: bool, map_folder: bool = False, image_origin: str = IMAGE_ORIGIN):
    """The default layout: 3-D view on the left; on the right the keyframe image (``images``, the entity
    ``image_origin``), the ATE over time (``ate``) and the loop table, with the run's notes or the map's
    summary as tabs."""
    rr = require_rerun()
    rrb = rr.blueprint
    side = []
    if images:
        name = "keyframe image and keypoints" if image_origin == IMAGE_ORIGIN else "keyframe image"
        side.append(rrb.Spatial2DView(origin=image_origin, name=name))
    if ate:
        side.append(rrb.TimeSeriesView(origin="ate", name="ATE over time (m)"))
    texts = [rrb.TextDocumentView(origin="loops/table", name="loops")]
    if not map_folder:
        texts.append(rrb.TextDocumentView(origin="info", name="run"))
        texts.append(rrb.TextLogView(origin="loops/events", name="loop events"))
    side.append(rrb.Tabs(*texts))
    return rrb.Blueprint(
        # the odometry's cloud is logged but not drawn at first: two clouds on top of each other hide both
        rrb.Horizontal(rrb.Spatial3DView(origin="world", name="map frame" if map_folder else "3-D",
                                         contents=["+ /world/**", "- /world/map/odometry"]),
                       rrb.Vertical(*side), column_shares=[3, 2]),
        rrb.BlueprintPanel(state="collapsed"), rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(state="collapsed" if map_folder else "expanded"),
    )
