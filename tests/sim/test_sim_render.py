"""Demo-world renderer: depth agrees with the world geometry, views are photometrically consistent,
the same place seen on different laps looks alike, aliasing sites really alias."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from slam_lcd.sim import T_body_camera, build_world, demo_camera, gt_loop_pairs, make_path, make_trajectory, render
from slam_lcd.sim.trajectory import START_NS


@pytest.fixture(scope="module")
def world():
    return build_world(0)


def _body(x, y, yaw):
    T = np.eye(4)
    c, s = np.cos(yaw), np.sin(yaw)
    T[:2, :2] = [[c, -s], [s, c]]
    T[0, 3], T[1, 3] = x, y
    return T


def _raycast_depth(world, cam, T_wc):
    """Independent reference: every pixel's ray against every plane rectangle, nearest hit's z."""
    ys, xs = np.mgrid[0:cam.height, 0:cam.width].astype(np.float64)
    rays_c = np.stack([(xs - cam.cx) / cam.fx, (ys - cam.cy) / cam.fy, np.ones_like(xs)], -1).reshape(-1, 3)
    R, t = T_wc[:3, :3], T_wc[:3, 3]
    rays_w = rays_c @ R.T
    best = np.full(len(rays_c), np.inf)
    for p in world.planes:
        n = p.normal
        denom = rays_w @ n
        with np.errstate(divide="ignore", invalid="ignore"):
            lam = ((p.origin - t) @ n) / denom  # ray parameter = camera z (rays have z = 1)
        hit = t + lam[:, None] * rays_w
        a = (hit - p.origin) @ p.u
        b = (hit - p.origin) @ p.v
        ok = (lam > 0.05) & (a >= 0) & (a <= p.width) & (b >= 0) & (b <= p.height)
        best = np.where(ok & (lam < best), lam, best)
    return best.reshape(cam.height, cam.width)


POSES = [(1.5, 1.5, 0.0), (12.5, 4.0, np.pi / 2), (2.0, 2.2, np.pi / 4), (5.0, 12.3, np.pi), (1.2, 9.0, -1.9)]


@pytest.mark.parametrize("pose", POSES)
def test_depth_matches_raycast_reference(world, pose):
    cam = demo_camera(160, 120)
    T_wc = _body(*pose) @ T_body_camera()
    _, depth = render(world, cam, T_wc)
    ref = _raycast_depth(world, cam, T_wc)
    assert np.isfinite(ref).all() and (depth > 0).all()
    rel = np.abs(depth - ref) / ref
    # silhouette pixels may go to the neighbouring plane; everything else is exact
    assert np.mean(rel < 1e-4) > 0.985, np.mean(rel < 1e-4)
    assert np.median(rel) < 1e-5


def _bilinear(img, uv):
    x, y = uv[:, 0], uv[:, 1]
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = x - x0, y - y0
    a, b = img[y0, x0], img[y0, x0 + 1]
    c, d = img[y0 + 1, x0], img[y0 + 1, x0 + 1]
    return (a * (1 - fx) + b * fx) * (1 - fy) + (c * (1 - fx) + d * fx) * fy


def _project(cam, T_wc, X):
    Xc = (X - T_wc[:3, 3]) @ T_wc[:3, :3]
    uv = np.column_stack([cam.fx * Xc[:, 0] / Xc[:, 2] + cam.cx, cam.fy * Xc[:, 1] / Xc[:, 2] + cam.cy])
    return uv, Xc[:, 2]


def test_sampled_world_points_reproject_within_half_a_pixel(world):
    """World points on the walls, seen by two cameras: back-projecting with the rendered depth of
    view A and projecting into view B lands within 0.5 px of the point's true projection in B;
    the rendered intensities at both projections agree (texture mapping is consistent)."""
    cam = demo_camera(640, 480)
    T_a = _body(4.0, 1.4, 0.1) @ T_body_camera()
    T_b = _body(5.2, 1.9, -0.15) @ T_body_camera()
    img_a, dep_a = render(world, cam, T_a)
    img_b, dep_b = render(world, cam, T_b)
    rng = np.random.default_rng(0)
    pts = []
    for p in world.planes:
        a = rng.uniform(0.05, p.width - 0.05, 300)
        b = rng.uniform(0.05, p.height - 0.05, 300)
        pts.append(p.origin + a[:, None] * p.u + b[:, None] * p.v)
    X = np.concatenate(pts)
    uv_a, z_a = _project(cam, T_a, X)
    uv_b, z_b = _project(cam, T_b, X)

    def inside(uv, z):
        return (z > 0.1) & (uv[:, 0] > 2) & (uv[:, 0] < cam.width - 3) & (uv[:, 1] > 2) & (uv[:, 1] < cam.height - 3)

    keep = inside(uv_a, z_a) & inside(uv_b, z_b)
    X, uv_a, z_a, uv_b, z_b = X[keep], uv_a[keep], z_a[keep], uv_b[keep], z_b[keep]
    # visible in both views: the rendered depth around the projection is the point's own depth
    vis_a = np.abs(_bilinear(1.0 / dep_a, uv_a) * z_a - 1.0) < 1e-4
    vis_b = np.abs(_bilinear(1.0 / dep_b, uv_b) * z_b - 1.0) < 1e-4
    sel = vis_a & vis_b
    assert sel.sum() > 300, sel.sum()
    X, uv_a, uv_b = X[sel], uv_a[sel], uv_b[sel]
    # back-project from A with A's depth (inverse depth is exactly bilinear on a plane)
    zr = 1.0 / _bilinear(1.0 / dep_a, uv_a)
    Xc = np.column_stack([(uv_a[:, 0] - cam.cx) / cam.fx * zr, (uv_a[:, 1] - cam.cy) / cam.fy * zr, zr])
    Xw = Xc @ T_a[:3, :3].T + T_a[:3, 3]
    assert np.percentile(np.linalg.norm(Xw - X, axis=1), 99) < 2e-3
    uv_b2, _ = _project(cam, T_b, Xw)
    err = np.linalg.norm(uv_b2 - uv_b, axis=1)
    assert err.max() < 0.5, err.max()
    # same texture seen from both views
    # (lightly blurred: the two views resample the texture at different scales and mip levels)
    ia = _bilinear(cv2.GaussianBlur(img_a, (0, 0), 1.0).astype(np.float64), uv_a)
    ib = _bilinear(cv2.GaussianBlur(img_b, (0, 0), 1.0).astype(np.float64), uv_b)
    print(f"photometric consistency: corr {np.corrcoef(ia, ib)[0, 1]:.3f}, "
          f"median |diff| {np.median(np.abs(ia - ib)):.2f}")
    assert np.corrcoef(ia, ib)[0, 1] > 0.9
    assert np.median(np.abs(ia - ib)) < 8.0
    # control: a 4-pixel misregistration is clearly visible to this check
    ic = _bilinear(cv2.GaussianBlur(img_b, (0, 0), 1.0).astype(np.float64),
                   np.clip(uv_b + (4.0, 0.0), 0, cam.width - 2))
    assert np.corrcoef(ia, ic)[0, 1] < np.corrcoef(ia, ib)[0, 1] - 0.1


def test_render_outputs_and_colour(world):
    cam = demo_camera(320, 240)
    T = _body(6.0, 1.5, 0.0) @ T_body_camera()
    gray, depth = render(world, cam, T)
    rgb, none = render(world, cam, T, color=True, with_depth=False)
    assert gray.shape == (240, 320) and gray.dtype == np.uint8
    assert rgb.shape == (240, 320, 3) and rgb.dtype == np.uint8 and none is None
    assert depth.dtype == np.float32 and depth.min() > 0.3 and depth.max() < 30.0
    assert gray.std() > 25  # textured, not flat
    # grey of the colour render is close to the grey render (same textures)
    diff = np.abs(cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY).astype(int) - gray.astype(int))
    assert np.median(diff) <= 2
    # lighting epochs change brightness mildly
    lit1, _ = render(world, cam, T, epoch=1.0, with_depth=False)
    ratio = lit1.mean() / gray.mean()
    assert 0.7 < ratio < 1.3 and abs(ratio - 1.0) > 0.01


def _orb_inliers(a, b):
    orb = cv2.ORB_create(1000)
    ka, da = orb.detectAndCompute(a, None)
    kb, db = orb.detectAndCompute(b, None)
    if da is None or db is None:
        return 0
    m = cv2.BFMatcher(cv2.NORM_HAMMING, crossCheck=True).match(da, db)
    if len(m) < 8:
        return 0
    pa = np.float32([ka[x.queryIdx].pt for x in m])
    pb = np.float32([kb[x.trainIdx].pt for x in m])
    _, mask = cv2.findFundamentalMat(pa, pb, cv2.FM_RANSAC, 1.0, 0.999)
    return int(mask.sum()) if mask is not None else 0


def test_same_place_on_different_laps_looks_alike(world):
    cam = demo_camera()
    Tbc = T_body_camera()
    gt = make_trajectory("laps")
    path = make_path("laps")
    pairs = gt_loop_pairs(gt, T_body_camera=Tbc)
    assert len(pairs) > 100
    rng = np.random.default_rng(3)
    sel = pairs[rng.choice(len(pairs), 6, replace=False)]

    def view(i):
        t = (gt.stamps[i] - START_NS) * 1e-9
        return render(world, cam, gt.poses[i] @ Tbc, epoch=float(path.laps_at(t)), with_depth=False)[0]

    same, diff = [], []
    looped = set(map(tuple, pairs.tolist()))
    for i, j in sel:
        a = view(i)
        same.append(_orb_inliers(a, view(j)))
        k = (j + len(gt) // 4) % len(gt)
        while (max(i, k), min(i, k)) in looped or abs(int(k) - int(i)) < 40:
            k = (k + 37) % len(gt)
        diff.append(_orb_inliers(a, view(k)))
    assert min(same) > 60, same
    assert max(diff) < 40, diff
    assert np.median(same) > 5 * np.median(diff), (same, diff)


def test_repeated_decals_alias_across_places(world):
    """The same decal group at two places gives many consistent matches: deliberate aliasing."""
    cam = demo_camera()
    by_group = {}
    for s in world.alias_sites:
        by_group.setdefault(s["group"], []).append(s)
    g0 = by_group[0]
    assert len(g0) >= 2
    views = []
    for s in g0[:2]:
        eye = s["centre"] + 2.2 * s["normal"]
        yaw = np.arctan2(-s["normal"][1], -s["normal"][0])
        views.append(render(world, cam, _body(eye[0], eye[1], yaw) @ T_body_camera(), with_depth=False)[0])
    assert np.linalg.norm(g0[0]["centre"] - g0[1]["centre"]) > 3.0
    assert _orb_inliers(views[0], views[1]) > 60
