"""Figures of a run and trajectory export: trajectory.png in a chosen plane or in
3-D, the corrected trajectory coloured by its error, accepted and rejected loops drawn
differently, short legends; `slam-lcd export` to a ROS1 bag and a rosbag2 folder."""
from __future__ import annotations

import numpy as np
import pytest

from slam_lcd.eval.plots import plot_run_trajectories
from slam_lcd.types import Trajectory


def _circle(n=200, z=0.0, noise=0.0, seed=0):
    rng = np.random.default_rng(seed)
    a = np.linspace(0, 2 * np.pi, n)
    P = np.tile(np.eye(4), (n, 1, 1))
    P[:, 0, 3], P[:, 1, 3], P[:, 2, 3] = 5 * np.cos(a), 5 * np.sin(a), z + 0.1 * np.sin(3 * a)
    P[:, :3, 3] += noise * rng.standard_normal((n, 3))
    return Trajectory(np.arange(n, dtype=np.int64) * 100_000_000, P)


@pytest.mark.parametrize("mode", ["auto", "xy", "xz", "yz", "xyz"])
def test_run_trajectory_plot_modes_loops_and_error_colours(mode, tmp_path):
    gt, odom, corr = _circle(), _circle(noise=0.3, seed=1), _circle(noise=0.05, seed=2)
    err = np.linalg.norm(corr.positions - gt.positions, axis=1)
    acc = [(corr.positions[0], corr.positions[-1]), (corr.positions[10], corr.positions[190])]
    rej = [(corr.positions[50], corr.positions[150])]
    fig = plot_run_trajectories(ground_truth=gt, odometry=odom, corrected=corr, corrected_errors=err,
                                accepted_edges=acc, rejected_edges=rej, mode=mode, out=tmp_path / "t.png")
    ax = fig.axes[0]
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert sorted(labels) == sorted(["ground truth", "odometry", "accepted loops (2)", "rejected loops (1)",
                                     "corrected (colour: error)"])  # short names, no file paths
    loops = {ln.get_label(): ln for ln in ax.lines if "loops" in ln.get_label()}
    assert loops["accepted loops (2)"].get_linestyle() == "-" and loops["rejected loops (1)"].get_linestyle() == "--"
    assert loops["accepted loops (2)"].get_color() != loops["rejected loops (1)"].get_color()
    coloured = ax.collections[-1]
    np.testing.assert_allclose(coloured.get_array(), 0.5 * (err[:-1] + err[1:]))
    assert (ax.name == "3d") == (mode == "xyz")
    if mode in ("xz", "yz"):
        assert ax.get_xlabel()[0] == mode[0] and ax.get_ylabel()[0] == mode[1]
    assert (tmp_path / "t.png").stat().st_size > 10_000


def test_run_writes_trajectory_and_error_figures(report_run):
    _, out, _ = report_run
    for name in ("trajectory.png", "ate_over_time.png"):
        assert (out / name).read_bytes()[:4] == b"\x89PNG"


def test_unknown_plot_mode_is_refused():
    from slam_lcd.config import load_config
    from slam_lcd.errors import ConfigError

    with pytest.raises(ConfigError):
        load_config("default", ["run.plot_mode=top"])
    assert load_config("default", ["run.plot_mode=xyz"]).run.plot_mode == "xyz"


@pytest.mark.parametrize("to,name", [("rosbag1", "traj.bag"), ("rosbag2", "traj_rosbag2")])
def test_export_to_ros1_bag_and_rosbag2(to, name, tmp_path, capsys):
    from slam_lcd.cli.main import main
    from slam_lcd.io.trajectory_files import write_tum
    from slam_lcd.sensors.trajectories import load_trajectory_source

    traj = _circle(50, z=1.0)
    write_tum(tmp_path / "in.tum", traj)
    out = tmp_path / name
    assert main(["export", str(tmp_path / "in.tum"), "--to", to, str(out), "--frame-id", "odom"]) == 0
    back = load_trajectory_source(f"{out}:/slam_lcd/trajectory")
    assert np.array_equal(back.stamps, traj.stamps)
    np.testing.assert_allclose(back.poses, traj.poses, atol=1e-9)
    from rosbags.highlevel import AnyReader

    with AnyReader([out]) as r:
        counts = {c.topic: c.msgcount for c in r.connections}
    assert counts == {"/slam_lcd/trajectory": 50, "/tf": 50, "/slam_lcd/trajectory/path": 1}


def test_many_loops_are_one_line_per_kind_whose_pieces_are_the_loops():
    """3,000 loops are drawn as one line per kind (matplotlib's cost is per artist), each loop a piece of it."""
    gt, odom, corr = _circle(), _circle(noise=0.3, seed=1), _circle(noise=0.05, seed=2)
    rng = np.random.default_rng(3)
    pairs = rng.integers(0, len(corr), (3000, 2))
    acc = [(corr.positions[i], corr.positions[j]) for i, j in pairs]
    rej = acc[:7]
    fig = plot_run_trajectories(ground_truth=gt, odometry=odom, corrected=corr, accepted_edges=acc,
                                rejected_edges=rej, mode="xy")
    ax = fig.axes[0]
    loops = [ln for ln in ax.lines if "loops" in ln.get_label()]
    assert sorted(ln.get_label() for ln in loops) == ["accepted loops (3000)", "rejected loops (7)"]
    accepted = next(ln for ln in loops if ln.get_label().startswith("accepted"))
    x, y = np.asarray(accepted.get_xdata(), float), np.asarray(accepted.get_ydata(), float)
    assert len(x) == 3 * 3000 - 1 and np.isnan(x[2::3]).all() and np.isnan(y[2::3]).all()
    ends = np.stack([x, y], axis=1)[np.arange(len(x)) % 3 != 2].reshape(-1, 2, 2)
    expected = np.array([(a[:2], b[:2]) for a, b in acc])
    np.testing.assert_array_equal(ends, expected)


def test_no_loops_draw_no_loop_line():
    gt, odom, corr = _circle(), _circle(noise=0.3, seed=1), _circle(noise=0.05, seed=2)
    fig = plot_run_trajectories(ground_truth=gt, odometry=odom, corrected=corr, mode="xyz")
    assert not [ln for ln in fig.axes[0].lines if "loops" in ln.get_label()]


def test_the_plot_module_loads_in_the_background_and_a_failure_is_silent():
    """run_log imports matplotlib while the log streams (the outputs at the end are the run's critical path);
    a module that cannot be imported there is left to the plots, which say what went wrong."""
    import subprocess
    import sys

    code = ("import sys, time\n"
            "from slam_lcd.run.runner import _import_in_background\n"
            "assert 'matplotlib' not in sys.modules\n"
            "_import_in_background('slam_lcd.eval.plots')\n"
            "_import_in_background('slam_lcd.no_such_module')\n"
            "t0 = time.time()\n"
            "while 'slam_lcd.eval.plots' not in sys.modules and time.time() - t0 < 60:\n"
            "    time.sleep(0.01)\n"
            "import slam_lcd.eval.plots\n"
            "assert 'matplotlib' in sys.modules and hasattr(slam_lcd.eval.plots, 'plot_run_trajectories')\n"
            "print('ok')\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr
