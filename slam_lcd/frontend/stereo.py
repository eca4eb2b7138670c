"""Disparities of left-image keypoints in a rectified stereo pair.

Right-image features are matched to the left ones only along the same row band and
within the disparity range (descriptor distance, ratio test, one-to-one), then every
match is refined to sub-pixel precision by a 1-D patch search (sum of absolute
differences over an 11x11 window, parabola through the three best costs).
"""
from __future__ import annotations

import cv2
import numpy as np

from ..features.matching import descriptor_distances
from ..types import Features
from .config import FrontendConfig
from .matching import DEFAULT_MAX_DISTANCE

HALF = 5  # half window of the sub-pixel refinement patch
SEARCH = 3  # +- pixels searched around the matched disparity


def refine_disparities(left: np.ndarray, right: np.ndarray, xy: np.ndarray, d0: np.ndarray) -> np.ndarray:
    """Sub-pixel disparities around ``d0`` for left pixels ``xy`` (NaN where unreliable).

    Zero-mean SAD over an 11x11 window at integer disparities ``d0 +- 3``; a parabola
    through the best cost and its neighbours gives the sub-pixel offset. A minimum at the
    border of the search range, or a window leaving the image, is rejected.
    """
    h, w = left.shape
    n = len(xy)
    out = np.full(n, np.nan)
    if n == 0:
        return out
    xi = np.round(xy[:, 0]).astype(int)
    yi = np.round(xy[:, 1]).astype(int)
    di = np.round(d0).astype(int)
    offs = np.arange(-HALF, HALF + 1)
    ok = (yi - HALF >= 0) & (yi + HALF < h) & (xi - HALF >= 0) & (xi + HALF < w)
    ys = np.clip(yi[:, None, None] + offs[None, :, None], 0, h - 1)  # (n, 11, 1)
    xs = np.clip(xi[:, None, None] + offs[None, None, :], 0, w - 1)  # (n, 1, 11)
    P = left[ys, xs].astype(np.float32)
    P -= P.mean(axis=(1, 2), keepdims=True)
    shifts = np.arange(-SEARCH, SEARCH + 1)
    costs = np.full((n, len(shifts)), np.inf, np.float32)
    for k, sh in enumerate(shifts):
        dd = di + sh
        xr = xi - dd
        valid = ok & (dd > 0) & (xr - HALF >= 0) & (xr + HALF < w)
        xs_r = np.clip(xr[:, None, None] + offs[None, None, :], 0, w - 1)
        Q = right[ys, xs_r].astype(np.float32)
        Q -= Q.mean(axis=(1, 2), keepdims=True)
        c = np.abs(P - Q).sum(axis=(1, 2))
        costs[valid, k] = c[valid]
    kbest = np.argmin(costs, axis=1)
    rows = np.arange(n)
    inner = (kbest > 0) & (kbest < len(shifts) - 1) & np.isfinite(costs[rows, kbest])
    k0 = np.clip(kbest - 1, 0, len(shifts) - 1)
    k2 = np.clip(kbest + 1, 0, len(shifts) - 1)
    c0, c1, c2 = costs[rows, k0], costs[rows, kbest], costs[rows, k2]
    inner &= np.isfinite(c0) & np.isfinite(c2)
    with np.errstate(invalid="ignore", divide="ignore"):
        den = c0 - 2 * c1 + c2
        off = np.where(den > 1e-9, 0.5 * (c0 - c2) / den, 0.0)
    off = np.clip(np.nan_to_num(off), -0.5, 0.5)
    d = di + shifts[kbest] + off + (xy[:, 0] - xi)
    out[inner] = d[inner]
    return out


def stereo_disparities(feats: Features, left: np.ndarray, right: np.ndarray, extractor,
                       conf: FrontendConfig) -> np.ndarray:
    """Disparity (px) per left keypoint, NaN where no reliable match exists."""
    n = len(feats)
    disp = np.full(n, np.nan)
    if n == 0:
        return disp
    fr = extractor.extract(right)
    if len(fr) < 2:
        return disp
    dx = feats.keypoints[:, 0][:, None] - fr.keypoints[:, 0][None, :]
    dy = np.abs(feats.keypoints[:, 1][:, None] - fr.keypoints[:, 1][None, :])
    ok = ((dy <= conf.stereo_max_row_diff_px) & (dx >= conf.stereo_min_disparity_px - 1.0)
          & (dx <= conf.stereo_max_disparity_px))
    dmax = DEFAULT_MAX_DISTANCE["uint8" if feats.descriptors.dtype == np.uint8 else "float"]
    if feats.descriptors.dtype == np.uint8:
        # only descriptor pairs inside the row band / disparity range are compared (masked matcher)
        bf = cv2.BFMatcher(cv2.NORM_HAMMING)
        mask = ok.astype(np.uint8)
        fwd = bf.knnMatch(feats.descriptors, fr.descriptors, k=2, mask=mask)
        back = bf.match(fr.descriptors, feats.descriptors, mask=np.ascontiguousarray(mask.T))
        back_of = np.full(len(fr), -1)
        for m in back:
            back_of[m.queryIdx] = m.trainIdx
        best = np.full(n, -1)
        for cand in fwd:
            if not cand:
                continue
            m = cand[0]
            if m.distance >= dmax or back_of[m.trainIdx] != m.queryIdx:
                continue
            if len(cand) > 1 and m.distance >= 0.9 * cand[1].distance:
                continue
            best[m.queryIdx] = m.trainIdx
    else:
        dist = np.where(ok, descriptor_distances(feats.descriptors, fr.descriptors), np.inf)
        b = dist.argmin(1)
        bd = dist[np.arange(n), b]
        second = np.partition(dist, 1, axis=1)[:, 1]
        back = dist.argmin(0)
        good = np.isfinite(bd) & (bd < dmax) & (back[b] == np.arange(n)) & (bd < 0.9 * second)
        best = np.where(good, b, -1)
    sel = np.flatnonzero(best >= 0)
    if len(sel) == 0:
        return disp
    d = refine_disparities(left, right, feats.keypoints[sel].astype(np.float64), dx[sel, best[sel]])
    d[d < conf.stereo_min_disparity_px] = np.nan
    disp[sel] = d
    return disp
