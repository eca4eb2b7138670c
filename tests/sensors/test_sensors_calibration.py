"""Calibration files in the public EuRoC (camN/sensor.yaml) and Kalibr (camchain.yaml) layouts.

The files are written here as the datasets publish them (EuRoC MH_01_easy cam0/cam1 values;
a Kalibr camchain of the same rig), plus malformed variants: each must fail in one line
that names the file and the key.
"""
from __future__ import annotations

import numpy as np
import pytest

from slam_lcd.errors import CalibrationError, FileMissingError
from slam_lcd.geometry import inv
from slam_lcd.sensors.calibration import load_calibration

EUROC_CAM0 = """\
# General sensor definitions.
sensor_type: camera
comment: VI-Sensor cam0 (MT9M034)

# Sensor extrinsics wrt. the body-frame.
T_BS:
  cols: 4
  rows: 4
  data: [0.0148655429818, -0.999880929698, 0.00414029679422, -0.0216401454975,
         0.999557249008, 0.0149672133247, 0.025715529948, -0.064676986768,
        -0.0257744366974, 0.00375618835797, 0.999660727178, 0.00981073058949,
         0.0, 0.0, 0.0, 1.0]

# Camera specific definitions.
rate_hz: 20
resolution: [752, 480]
camera_model: pinhole
intrinsics: [458.654, 457.296, 367.215, 248.375] #fu, fv, cu, cv
distortion_model: radial-tangential
distortion_coefficients: [-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05]
"""

EUROC_CAM1 = """\
# General sensor definitions.
sensor_type: camera
comment: VI-Sensor cam1 (MT9M034)

# Sensor extrinsics wrt. the body-frame.
T_BS:
  cols: 4
  rows: 4
  data: [0.0125552670891, -0.999755099723, 0.0182237714554, -0.0198435579556,
         0.999598781151, 0.0130119051815, 0.0251588363115, 0.0453689425024,
        -0.0253898008918, 0.0179005838253, 0.999517347078, 0.00786212447038,
         0.0, 0.0, 0.0, 1.0]

# Camera specific definitions.
rate_hz: 20
resolution: [752, 480]
camera_model: pinhole
intrinsics: [457.587, 456.134, 379.999, 255.238] #fu, fv, cu, cv
distortion_model: radial-tangential
distortion_coefficients: [-0.28368365, 0.07451284, -0.00010473, -3.55590700e-05]
"""


def _rows(T):
    return "\n".join("  - [" + ", ".join(f"{v:.12f}" for v in row) + "]" for row in T)


def _euroc_T(text):
    import yaml

    return np.array(yaml.safe_load(text)["T_BS"]["data"], float).reshape(4, 4)


def kalibr_camchain(distortion="radtan", coeffs0="[-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05]"):
    """A Kalibr camchain.yaml of the EuRoC rig (T_cam_imu = inv(T_BS); cam1's T_cn_cnm1)."""
    T_b_c0, T_b_c1 = _euroc_T(EUROC_CAM0), _euroc_T(EUROC_CAM1)
    return f"""\
cam0:
  T_cam_imu:
{_rows(inv(T_b_c0))}
  cam_overlaps: [1]
  camera_model: pinhole
  distortion_coeffs: {coeffs0}
  distortion_model: {distortion}
  intrinsics: [458.654, 457.296, 367.215, 248.375]
  resolution: [752, 480]
  rostopic: /cam0/image_raw
cam1:
  T_cam_imu:
{_rows(inv(T_b_c1))}
  T_cn_cnm1:
{_rows(inv(T_b_c1) @ T_b_c0)}
  cam_overlaps: [0]
  camera_model: pinhole
  distortion_coeffs: [-0.28368365, 0.07451284, -0.00010473, -3.55590700e-05]
  distortion_model: {distortion}
  intrinsics: [457.587, 456.134, 379.999, 255.238]
  resolution: [752, 480]
  rostopic: /cam1/image_raw
"""


def _write(tmp_path, name, text):
    p = tmp_path / name
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(text)
    return p


def test_euroc_sensor_yaml_pair(tmp_path):
    c0 = _write(tmp_path, "cam0/sensor.yaml", EUROC_CAM0)
    c1 = _write(tmp_path, "cam1/sensor.yaml", EUROC_CAM1)
    before = (c0.read_bytes(), c1.read_bytes())
    calib = load_calibration([c0, c1])
    assert calib.kind == "euroc" and [c.name for c in calib.cameras] == ["cam0", "cam1"]
    cam = calib.cameras[0].camera
    assert (cam.width, cam.height) == (752, 480)
    assert (cam.fx, cam.fy, cam.cx, cam.cy) == (458.654, 457.296, 367.215, 248.375)
    assert cam.distortion_model == "plumb_bob"
    assert np.allclose(cam.D, [-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05])
    assert np.allclose(calib.cameras[0].T_body_camera, _euroc_T(EUROC_CAM0), atol=1e-6)
    # the EuRoC stereo baseline is about 11 cm
    assert 0.105 < cam.baseline < 0.115
    assert calib.cameras[1].camera.baseline is None  # no camera after cam1
    assert (c0.read_bytes(), c1.read_bytes()) == before  # inputs untouched


def test_kalibr_camchain_matches_euroc_files(tmp_path):
    calib = load_calibration(_write(tmp_path, "camchain.yaml", kalibr_camchain()))
    assert calib.kind == "kalibr" and len(calib.cameras) == 2
    c0, c1 = calib.cameras
    assert c0.rostopic == "/cam0/image_raw" and calib.camera_for("/cam1/image_raw") is c1
    assert calib.camera_for("/other") is c0
    assert np.allclose(c0.T_body_camera, _euroc_T(EUROC_CAM0), atol=1e-6)
    assert np.allclose(c1.T_body_camera, _euroc_T(EUROC_CAM1), atol=1e-6)
    partner, T_c1_c0 = calib.stereo_partner(c0)
    assert partner is c1 and np.allclose(T_c1_c0, inv(_euroc_T(EUROC_CAM1)) @ _euroc_T(EUROC_CAM0), atol=1e-6)
    euroc = load_calibration([_write(tmp_path, "a/sensor.yaml", EUROC_CAM0),
                              _write(tmp_path, "b/sensor.yaml", EUROC_CAM1)])
    assert c0.camera.baseline == pytest.approx(euroc.cameras[0].camera.baseline, abs=1e-6)


def test_kalibr_equidistant_and_cam1_from_chain_only(tmp_path):
    text = kalibr_camchain("equidistant", "[0.01, -0.002, 0.0003, -0.0001]")
    # cam1 without its own T_cam_imu: placed on the body through cam0 and T_cn_cnm1
    lines = text.splitlines()
    i = lines.index("cam1:")
    text = "\n".join(lines[: i + 1] + lines[i + 6:]) + "\n"
    calib = load_calibration(_write(tmp_path, "camchain.yaml", text))
    c0, c1 = calib.cameras
    assert c0.camera.distortion_model == "equidistant" and c0.camera.D.size == 4
    assert np.allclose(c1.T_body_camera, _euroc_T(EUROC_CAM1), atol=1e-6)


def test_opencv_yaml_header_is_accepted(tmp_path):
    calib = load_calibration(_write(tmp_path, "sensor.yaml", "%YAML:1.0\n" + EUROC_CAM0))
    assert calib.cameras[0].camera.fx == 458.654


BAD_EUROC = {
    "no intrinsics": (EUROC_CAM0.replace("intrinsics: [458.654, 457.296, 367.215, 248.375] #fu, fv, cu, cv\n", ""),
                      "intrinsics is missing"),
    "three intrinsics": (EUROC_CAM0.replace("[458.654, 457.296, 367.215, 248.375]", "[458.654, 457.296, 367.215]"),
                         "intrinsics must hold 4"),
    "text intrinsics": (EUROC_CAM0.replace("[458.654, 457.296, 367.215, 248.375]", "fu fv cu cv"),
                        "intrinsics must be a list of numbers"),
    "T_BS not rigid": (EUROC_CAM0.replace("0.0148655429818, -0.999880929698", "1.5, -0.999880929698"),
                       "T_BS.data is not a rigid transform"),
    "T_BS 3x4": (EUROC_CAM0.replace("rows: 4", "rows: 3"), "T_BS must be 4x4"),
    "T_BS without data": (EUROC_CAM0.replace("  data:", "  values:"), "T_BS.data is missing"),
    "unknown distortion": (EUROC_CAM0.replace("radial-tangential", "fov"), "distortion_model is 'fov'"),
    "coefficient count": (EUROC_CAM0.replace("-0.28340811, ", ""), "distortion_coefficients holds 3 numbers"),
    "not a camera": (EUROC_CAM0.replace("sensor_type: camera", "sensor_type: imu"), "sensor_type is 'imu'"),
    "bad yaml": (EUROC_CAM0.replace("rate_hz: 20", "rate_hz: [20"), "not valid YAML"),
    "a list": ("- 1\n- 2\n", "expected a YAML mapping"),
    "other mapping": ("foo: 1\n", "no key cam0"),
}

BAD_KALIBR = {
    "cam1 without T_cn_cnm1": (lambda t: t.replace("  T_cn_cnm1:", "  T_cx:"), "cam1.T_cn_cnm1 is missing"),
    "omni camera": (lambda t: t.replace("camera_model: pinhole", "camera_model: omni", 1),
                    "cam0.camera_model is 'omni'"),
    "no resolution": (lambda t: t.replace("  resolution: [752, 480]\n  rostopic: /cam1", "  rostopic: /cam1"),
                      "cam1.resolution is missing"),
    "zero focal": (lambda t: t.replace("[458.654, 457.296", "[0.0, 457.296"), "cam0.intrinsics has a non-positive"),
    "gap": (lambda t: t.replace("cam1:", "cam2:"), "cam0, cam1, ... without gaps"),
}


@pytest.mark.parametrize("case", sorted(BAD_EUROC))
def test_malformed_euroc_names_file_and_key(tmp_path, case):
    text, expected = BAD_EUROC[case]
    p = _write(tmp_path, "cam0/sensor.yaml", text)
    with pytest.raises(CalibrationError) as e:
        load_calibration(p)
    msg = str(e.value)
    assert "\n" not in msg and str(p) in msg and expected in msg, msg


@pytest.mark.parametrize("case", sorted(BAD_KALIBR))
def test_malformed_kalibr_names_file_and_key(tmp_path, case):
    edit, expected = BAD_KALIBR[case]
    p = _write(tmp_path, "camchain.yaml", edit(kalibr_camchain()))
    with pytest.raises(CalibrationError) as e:
        load_calibration(p)
    msg = str(e.value)
    assert "\n" not in msg and str(p) in msg and expected in msg, msg


def test_missing_file(tmp_path):
    with pytest.raises(FileMissingError):
        load_calibration(tmp_path / "camchain.yaml")


def test_cli_bad_calibration_is_one_line_exit_2(tmp_path, capsys):
    from slam_lcd.cli.main import main
    from slam_lcd.sim.demo_log import make_demo_log

    log = tmp_path / "demo.mcap"
    make_demo_log(log, frames=3, width=160, height=120, workers=0)
    bad = _write(tmp_path, "camchain.yaml", kalibr_camchain().replace("  T_cn_cnm1:", "  T_cx:"))
    rc = main(["run", str(log), "--out", str(tmp_path / "out"), "--calib", str(bad), "--no-progress"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "camchain.yaml" in err[0] and "cam1.T_cn_cnm1" in err[0], err
    assert not (tmp_path / "out").exists()


def test_missing_camera_info_hint_names_the_calibration_beside_the_log(tmp_path):
    from slam_lcd.sensors.calibration import missing_camera_info_hint

    base = ("the log has no CameraInfo for /cam0/image_raw: give the camera calibration with --calib FILE "
            "(a Kalibr camchain.yaml, or EuRoC's cam0/sensor.yaml then cam1/sensor.yaml)")
    log = tmp_path / "V1_01_easy.bag"
    assert missing_camera_info_hint(log, "/cam0/image_raw") == base
    for cam in ("cam0", "cam1"):  # an ASL folder beside the bag
        (tmp_path / "mav0" / cam).mkdir(parents=True)
        (tmp_path / "mav0" / cam / "sensor.yaml").write_text("sensor_type: camera\n", encoding="utf-8")
    assert missing_camera_info_hint(log, "/cam0/image_raw") == (
        f"{base}; beside the log: --calib {tmp_path}/mav0/cam0/sensor.yaml --calib {tmp_path}/mav0/cam1/sensor.yaml")
    (tmp_path / "camchain.yaml").write_text("cam0: {}\n", encoding="utf-8")  # a single camchain comes first
    want = f"{base}; beside the log: --calib {tmp_path}/camchain.yaml"
    assert missing_camera_info_hint(log, "/cam0/image_raw") == want
