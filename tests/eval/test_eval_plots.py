"""Plotting helpers of slam_lcd.eval (Agg backend; figures returned and PNGs written atomically)."""
from __future__ import annotations

import numpy as np

from slam_lcd.eval import ate
from slam_lcd.eval.plots import auto_plane, plot_error_over_time, plot_trajectories_top, save_figure
from slam_lcd.io.trajectory_files import read_trajectory


def test_top_view_with_several_trajectories_and_loop_edges(fr2, tmp_path):
    ref, est = fr2
    res = ate(ref, est, "sim3")
    edges = [(ref.positions[0], ref.positions[-1]), (ref.positions[100], ref.positions[5000])]
    out = tmp_path / "top.png"
    fig = plot_trajectories_top(
        [("ground truth", ref), ("ORB (Sim(3))", res.est_aligned)], loop_edges=edges, out=out,
        title=f"fr2/desk ({res.alignment.label})",
    )
    ax = fig.axes[0]
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert labels[0].startswith("ground truth") and labels[1].startswith("ORB")
    assert "loop edges (2)" in labels
    assert "Sim(3)" in ax.get_title()
    # plotted data are the trajectories' own positions
    np.testing.assert_allclose(ax.lines[0].get_xdata(), ref.positions[:, 0])
    assert out.read_bytes()[:4] == b"\x89PNG"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["top.png"]  # no temporary left behind


def test_error_over_time_names_alignment(fr2, tmp_path):
    ref, est = fr2
    a, b = ate(ref, est, "se3"), ate(ref, est, "sim3")
    fig = plot_error_over_time([("se3", a), ("sim3", b)])
    ax = fig.axes[0]
    assert len(ax.lines) == 2
    assert "SE(3)" in ax.get_title() and "Sim(3)" in ax.get_title()
    np.testing.assert_allclose(ax.lines[1].get_ydata(), b.errors)
    assert ax.lines[0].get_xdata()[0] == 0.0
    path = save_figure(fig, tmp_path / "sub" / "err.png")
    assert path.is_file() and path.stat().st_size > 5000


def test_auto_plane_picks_largest_extent(shared_data):
    kitti = read_trajectory(shared_data / "trajectories" / "KITTI_00_gt.txt")
    assert auto_plane(kitti.positions) == "xz"  # KITTI poses are camera frames: y points down
    assert auto_plane(np.c_[np.arange(5.0), np.arange(5.0) * 2, np.zeros(5)]) == "xy"
