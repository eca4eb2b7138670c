"""PLY and PCD files of a cloud: x y z float32 and red green blue uint8 per point, binary little-endian.

Why both: PLY (through ``plyfile``) opens in MeshLab, CloudCompare, Blender and Open3D; PCD is
what the ROS / PCL tools (``pcl_viewer``, RTAB-Map's exports) take. PCD's fields are written by
hand (a short text header, then the points): the format needs no library. Files are written
atomically (a temporary name, then renamed into place); reading checks the header and says
what is wrong in one line (:class:`~slam_lcd.errors.InputError`).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError, UnsupportedFormatError
from ..files.atomic import atomic_path
from .voxel_grid import Cloud

SUFFIXES = (".ply", ".pcd")
_PLY_DT = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("red", "u1"), ("green", "u1"), ("blue", "u1")])


def cloud_suffix(path: str | Path) -> str:
    suffix = Path(path).suffix.lower()
    if suffix not in SUFFIXES:
        raise UnsupportedFormatError(
            f"cloud files are {' or '.join(SUFFIXES)}, not {suffix or 'a name without suffix'!r}", path)
    return suffix


def _records(cloud: Cloud) -> np.ndarray:
    rec = np.empty(len(cloud), _PLY_DT)
    for i, k in enumerate("xyz"):
        rec[k] = cloud.points[:, i]
    for i, k in enumerate(("red", "green", "blue")):
        rec[k] = cloud.colours[:, i]
    return rec


def _pcd_header(n: int) -> bytes:
    return ("# .PCD v0.7 - Point Cloud Data file format (slam-lcd map)\nVERSION 0.7\nFIELDS x y z rgb\n"
            "SIZE 4 4 4 4\nTYPE F F F U\nCOUNT 1 1 1 1\n"
            f"WIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA binary\n").encode("ascii")


def write_cloud(path: str | Path, cloud: Cloud, comment: str = "") -> Path:
    """Write ``cloud`` as ``.ply`` or ``.pcd`` (by the suffix), atomically."""
    from plyfile import PlyData, PlyElement

    path = Path(path)
    suffix = cloud_suffix(path)
    with atomic_path(path) as tmp:
        if suffix == ".ply":
            el = PlyElement.describe(_records(cloud), "vertex")
            PlyData([el], text=False, byte_order="<", comments=[c for c in comment.splitlines() if c]).write(str(tmp))
        else:
            c = cloud.colours.astype(np.uint32)
            rec = np.empty(len(cloud), [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("rgb", "<u4")])
            for i, k in enumerate("xyz"):
                rec[k] = cloud.points[:, i]
            rec["rgb"] = (c[:, 0] << 16) | (c[:, 1] << 8) | c[:, 2]
            with open(tmp, "wb") as fh:
                fh.write(_pcd_header(len(cloud)))
                fh.write(rec.tobytes())
    return path


def read_cloud(path: str | Path) -> Cloud:
    """A cloud written by :func:`write_cloud` (PLY: any file with x y z and, optionally, red green blue)."""
    path = Path(path)
    suffix = cloud_suffix(path)
    if not path.is_file():
        raise InputError("no such cloud file", path)
    if suffix == ".ply":
        from plyfile import PlyData

        try:
            v = PlyData.read(str(path))["vertex"].data
            pts = np.column_stack([v["x"], v["y"], v["z"]]).astype(np.float32)
            names = v.dtype.names
            col = (np.column_stack([v["red"], v["green"], v["blue"]]).astype(np.uint8)
                   if {"red", "green", "blue"} <= set(names) else np.full((len(v), 3), 128, np.uint8))
        except (KeyError, ValueError, IndexError, OSError) as e:
            raise InputError(f"not a PLY point cloud this reads ({e.__class__.__name__}: {e})", path) from None
        return Cloud(pts.reshape(-1, 3), col.reshape(-1, 3))
    data = path.read_bytes()
    end = data.find(b"DATA binary\n")
    if not data.startswith(b"# .PCD") or end < 0:
        raise InputError("not a binary PCD file written by slam-lcd", path)
    n = int(next(ln.split()[1] for ln in data[:end].decode("ascii").splitlines() if ln.startswith("POINTS")))
    rec = np.frombuffer(data[end + len(b"DATA binary\n"):], [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("rgb", "<u4")])
    if len(rec) != n:
        raise InputError(f"PCD header says {n} points, the file holds {len(rec)}", path)
    rgb = rec["rgb"]
    col = np.column_stack([(rgb >> 16) & 255, (rgb >> 8) & 255, rgb & 255]).astype(np.uint8)
    return Cloud(np.column_stack([rec["x"], rec["y"], rec["z"]]).astype(np.float32), col)
