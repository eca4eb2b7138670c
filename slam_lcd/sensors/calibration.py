"""Camera calibration files for logs without (or with wrong) CameraInfo: Kalibr and EuRoC.

Public benchmark bags (EuRoC, most Kalibr-calibrated rigs) carry no ``CameraInfo``; the
intrinsics, distortion and extrinsics live in a file beside the bag:

- Kalibr ``camchain.yaml``: ``cam0``, ``cam1``, … each with ``camera_model: pinhole``,
  ``intrinsics: [fu, fv, pu, pv]``, ``distortion_model: radtan | equidistant``,
  ``distortion_coeffs``, ``resolution: [w, h]``, optionally ``rostopic``, ``T_cam_imu``
  (maps IMU points into the camera) and, from ``cam1`` on, ``T_cn_cnm1`` (maps points of
  the previous camera into this one);
- EuRoC ``camN/sensor.yaml``: one camera per file, ``sensor_type: camera``,
  ``T_BS: {cols: 4, rows: 4, data: [16 numbers]}`` (maps sensor points into the body
  frame), ``resolution``, ``camera_model: pinhole``, ``intrinsics: [fu, fv, cu, cv]``,
  ``distortion_model: radial-tangential | equidistant``, ``distortion_coefficients``.

Both become :class:`Calibration`: one :class:`CalibratedCamera` per camera, in file order
(cam0 first), each with its :class:`~slam_lcd.types.CameraModel` and, when the file says,
``T_body_camera`` (body = the IMU for Kalibr, EuRoC's body frame for ``T_BS``). The stereo
extrinsic ``T_cam1_cam0`` gives the baseline (its translation's length). A file is read with
``yaml.safe_load``; a missing or malformed key raises :class:`CalibrationError` naming the
file and the key (``cam1.T_cn_cnm1``), one line.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from ..errors import CalibrationError, FileMissingError, InputError
from ..geometry import inv
from ..types import CameraModel
from ..vision.camera import normalise_camera

# the file's distortion name -> CameraModel.distortion_model
_DISTORTIONS = {"radtan": "plumb_bob", "radial-tangential": "plumb_bob", "plumb_bob": "plumb_bob",
                "equidistant": "equidistant", "equi": "equidistant", "fisheye": "equidistant",
                "none": "none"}
_COEFF_COUNTS = {"plumb_bob": (4, 5), "equidistant": (4,), "none": (0,)}


@dataclass
class CalibratedCamera:
    """One camera of a calibration file."""

    name: str  # cam0, cam1, ... (EuRoC: the file's camera index in the order given)
    camera: CameraModel
    T_body_camera: np.ndarray | None = None  # None: the file does not place the camera on the body
    T_this_previous: np.ndarray | None = None  # Kalibr T_cn_cnm1 (None for cam0)
    rostopic: str | None = None


@dataclass
class Calibration:
    """The cameras of one or more calibration files, cam0 first."""

    cameras: list[CalibratedCamera]
    sources: list[Path] = field(default_factory=list)
    kind: str = ""  # 'kalibr' | 'euroc'

    def describe(self) -> str:
        names = ", ".join(str(s) for s in self.sources)
        return f"{self.kind} calibration {names} ({len(self.cameras)} camera{'s' if len(self.cameras) != 1 else ''})"

    def camera_for(self, image_topic: str | None) -> CalibratedCamera:
        """The camera whose ``rostopic`` is ``image_topic``, else cam0."""
        for c in self.cameras:
            if image_topic and c.rostopic and c.rostopic.strip("/") == image_topic.strip("/"):
                return c
        return self.cameras[0]

    def stereo_partner(self, cam: CalibratedCamera) -> tuple[CalibratedCamera, np.ndarray] | None:
        """The next camera and ``T_next_this`` (maps points of ``cam`` into the next camera), or None."""
        i = self.cameras.index(cam)
        if i + 1 >= len(self.cameras):
            return None
        nxt = self.cameras[i + 1]
        if nxt.T_this_previous is not None:
            return nxt, nxt.T_this_previous
        if nxt.T_body_camera is not None and cam.T_body_camera is not None:
            return nxt, inv(nxt.T_body_camera) @ cam.T_body_camera
        return None


def load_calibration(paths) -> Calibration:
    """Read one Kalibr camchain.yaml, or one or more EuRoC sensor.yaml files (cam0 first)."""
    paths = [Path(p) for p in ([paths] if isinstance(paths, (str, Path)) else paths)]
    if not paths:
        raise InputError("no calibration file given")
    docs = [(p, _read_yaml(p)) for p in paths]
    kinds = [_kind_of(p, d) for p, d in docs]
    if "kalibr" in kinds:
        if len(docs) > 1:
            raise CalibrationError("a Kalibr camchain.yaml holds every camera; give it alone (one --calib)", paths[0])
        cameras = _kalibr_cameras(*docs[0])
    else:
        cameras = [_euroc_camera(p, d, f"cam{i}") for i, (p, d) in enumerate(docs)]
    calib = Calibration(cameras, paths, kinds[0])
    for cam in cameras:  # the stereo baseline of each camera that has a partner
        partner = calib.stereo_partner(cam)
        if partner is not None:
            cam.camera.baseline = float(np.linalg.norm(partner[1][:3, 3]))
    return calib


def missing_camera_info_hint(log_path: str | Path, image_topic: str) -> str:
    """What to give when a log has no CameraInfo for ``image_topic``: ``--calib FILE``, naming the
    calibration beside the log when there is one (``camchain-<log>.yaml`` as ``make-demo-log`` writes
    it, a single ``camchain*.yaml``, or EuRoC's ``cam0/sensor.yaml`` of an ASL folder)."""
    log_path = Path(log_path)
    folder = log_path.parent
    chains = sorted(folder.glob("camchain*.yaml"))
    own = folder / f"camchain-{log_path.stem}.yaml"
    beside: list[Path] = [own] if own.is_file() else chains if len(chains) == 1 else []
    if not beside:
        asl = [folder / d / "cam0" / "sensor.yaml" for d in ("", "mav0")]
        cam0 = next((p for p in asl if p.is_file()), None)
        if cam0 is not None:
            cam1 = cam0.parent.parent / "cam1" / "sensor.yaml"
            beside = [cam0] + ([cam1] if cam1.is_file() else [])
    text = (f"the log has no CameraInfo for {image_topic}: give the camera calibration with --calib FILE "
            "(a Kalibr camchain.yaml, or EuRoC's cam0/sensor.yaml then cam1/sensor.yaml)")
    if beside:
        text += f"; beside the log: {' '.join(f'--calib {p}' for p in beside)}"
    return text


# ---------------------------------------------------------------------------- reading
def _read_yaml(path: Path):
    if not path.is_file():
        raise FileMissingError("calibration file not found (--calib)", path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise CalibrationError(f"cannot read the calibration file ({e})", path) from None
    if text.startswith("%YAML:"):  # OpenCV FileStorage header (some EuRoC-style files): not YAML 1.1
        text = text.split("\n", 1)[1] if "\n" in text else ""
    try:
        doc = yaml.safe_load(text)
    except yaml.YAMLError as e:
        raise CalibrationError(f"not valid YAML ({' '.join(str(e).split())[:200]})", path) from None
    if not isinstance(doc, dict):
        raise CalibrationError("not a calibration file: expected a YAML mapping (Kalibr camchain.yaml with cam0, ..., "
                               "or EuRoC sensor.yaml with T_BS and intrinsics)", path)
    return doc


def _kind_of(path: Path, doc: dict) -> str:
    if isinstance(doc.get("cam0"), dict):
        return "kalibr"
    if "intrinsics" in doc or "T_BS" in doc or "sensor_type" in doc:
        return "euroc"
    raise CalibrationError(f"not a calibration file this reads: no key cam0 (Kalibr camchain.yaml) and no intrinsics "
                           f"(EuRoC sensor.yaml); keys: {', '.join(map(str, doc)) or '(none)'}", path)


def _need(doc: dict, key: str, path: Path, prefix: str = ""):
    if key not in doc or doc[key] is None:
        raise CalibrationError(f"key {prefix}{key} is missing", path)
    return doc[key]


def _numbers(value, key: str, path: Path, count=None) -> np.ndarray:
    """A flat list of finite numbers (``count``: the lengths allowed)."""
    try:
        arr = np.asarray(value, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise CalibrationError(f"key {key} must be a list of numbers, got {value!r:.80}", path) from None
    if isinstance(value, (str, bytes, dict)) or np.ndim(value) == 0:
        raise CalibrationError(f"key {key} must be a list of numbers, got {value!r:.80}", path)
    if count is not None and arr.size not in count:
        raise CalibrationError(f"key {key} must hold {' or '.join(map(str, count))} numbers, got {arr.size}", path)
    if not np.all(np.isfinite(arr)):
        raise CalibrationError(f"key {key} holds NaN or inf", path)
    return arr


def _rigid(M, key: str, path: Path) -> np.ndarray:
    """A 4x4 rigid transform (rotation orthonormal to 1e-3, last row 0 0 0 1)."""
    T = _numbers(M, key, path, (16,)).reshape(4, 4)
    R = T[:3, :3]
    if not np.allclose(T[3], [0, 0, 0, 1], atol=1e-9) or not np.allclose(R @ R.T, np.eye(3), atol=1e-3) \
            or np.linalg.det(R) < 0:
        raise CalibrationError(f"key {key} is not a rigid transform (rotation part not orthonormal or last row "
                               "not 0 0 0 1)", path)
    U, _, Vt = np.linalg.svd(R)  # files print 9-digit rotations: the nearest rotation
    T[:3, :3] = U @ Vt
    return T


def _camera(path: Path, prefix: str, model: str, intrinsics, dist_model: str, coeffs, coeff_key: str,
            resolution) -> CameraModel:
    if str(model).lower() != "pinhole":
        raise CalibrationError(f"key {prefix}camera_model is {model!r}; only pinhole cameras are supported", path)
    fu, fv, cu, cv = _numbers(intrinsics, f"{prefix}intrinsics", path, (4,))
    if fu <= 0 or fv <= 0:
        raise CalibrationError(f"key {prefix}intrinsics has a non-positive focal length ({fu}, {fv})", path)
    dist = _DISTORTIONS.get(str(dist_model).lower())
    if dist is None:
        raise CalibrationError(f"key {prefix}distortion_model is {dist_model!r}; supported: radtan "
                               "(radial-tangential), equidistant, none", path)
    D = _numbers(coeffs, prefix + coeff_key, path) if coeffs is not None else np.zeros(0)
    if D.size not in _COEFF_COUNTS[dist] and np.any(D):
        raise CalibrationError(f"key {prefix}{coeff_key} holds {D.size} numbers; distortion model {dist_model!r} "
                               f"takes {' or '.join(map(str, _COEFF_COUNTS[dist]))}", path)
    w, h = _numbers(resolution, f"{prefix}resolution", path, (2,))
    if w <= 0 or h <= 0 or w != math.floor(w) or h != math.floor(h):
        raise CalibrationError(f"key {prefix}resolution must be two positive integers [width, height]", path)
    cam = CameraModel(width=int(w), height=int(h), fx=float(fu), fy=float(fv), cx=float(cu), cy=float(cv),
                      distortion_model=dist, D=D)
    return normalise_camera(cam)


def _kalibr_cameras(path: Path, doc: dict) -> list[CalibratedCamera]:
    names = sorted((k for k in doc if isinstance(k, str) and k.startswith("cam") and k[3:].isdigit()),
                   key=lambda k: int(k[3:]))
    if [int(n[3:]) for n in names] != list(range(len(names))):
        raise CalibrationError(f"cameras must be cam0, cam1, ... without gaps; found {', '.join(names)}", path)
    cams: list[CalibratedCamera] = []
    for name in names:
        c = doc[name]
        p = f"{name}."
        if not isinstance(c, dict):
            raise CalibrationError(f"key {name} must be a mapping of camera keys", path)
        camera = _camera(path, p, _need(c, "camera_model", path, p), _need(c, "intrinsics", path, p),
                         _need(c, "distortion_model", path, p), c.get("distortion_coeffs"), "distortion_coeffs",
                         _need(c, "resolution", path, p))
        T_cam_imu = _rigid(c["T_cam_imu"], f"{p}T_cam_imu", path) if c.get("T_cam_imu") is not None else None
        T_prev = None
        if cams:
            T_prev = _rigid(_need(c, "T_cn_cnm1", path, p), f"{p}T_cn_cnm1", path)
        T_bc = inv(T_cam_imu) if T_cam_imu is not None else None
        if T_bc is None and T_prev is not None and cams[-1].T_body_camera is not None:
            T_bc = cams[-1].T_body_camera @ inv(T_prev)  # body <- previous camera <- this camera
        topic = c.get("rostopic")
        cams.append(CalibratedCamera(name, camera, T_bc, T_prev, str(topic) if topic else None))
    return cams


def _euroc_camera(path: Path, doc: dict, name: str) -> CalibratedCamera:
    if "sensor_type" in doc and str(doc["sensor_type"]).lower() != "camera":
        raise CalibrationError(f"key sensor_type is {doc['sensor_type']!r}, not camera (give the camN/sensor.yaml "
                               "files)", path)
    camera = _camera(path, "", doc.get("camera_model", "pinhole"), _need(doc, "intrinsics", path),
                     _need(doc, "distortion_model", path), _need(doc, "distortion_coefficients", path),
                     "distortion_coefficients", _need(doc, "resolution", path))
    T_bs = _need(doc, "T_BS", path)
    if not isinstance(T_bs, dict):
        raise CalibrationError("key T_BS must be a mapping {cols: 4, rows: 4, data: [16 numbers]}", path)
    rows, cols = _need(T_bs, "rows", path, "T_BS."), _need(T_bs, "cols", path, "T_BS.")
    if rows != 4 or cols != 4:
        raise CalibrationError(f"key T_BS must be 4x4, says rows: {rows}, cols: {cols}", path)
    T_body_camera = _rigid(_need(T_bs, "data", path, "T_BS."), "T_BS.data", path)
    return CalibratedCamera(name, camera, T_body_camera)
