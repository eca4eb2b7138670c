"""Ground-truth robot trajectories through the demo world: laps around block A or B, or a figure eight.

A path is a closed centre line through the corridors (straight runs joined by circular
arcs of radius 1.2 m), driven repeatedly. On top of it the robot weaves gently left and
right (two sines whose periods do not divide the lap), so each lap passes a place at a
slightly different position and heading, as a real robot would. Speed is ~1.1 m/s on
straight runs and slows to ~0.7 m/s in the turns; the run starts from 0.3 m/s.

The body frame is planar (z = 0, no roll or pitch): x forward, y left, z up.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..types import Trajectory

START_NS = 1_700_000_000_000_000_000  # first stamp of every demo log (2023-11-14T22:13:20Z)
TURN_RADIUS = 1.2
STEP = 0.01  # dense sampling of the path (m)

WAYPOINTS = {
    # counter-clockwise around block A (block on the robot's left)
    "laps": [(1.5, 1.5), (12.5, 1.5), (12.5, 12.5), (1.5, 12.5)],
    # around A counter-clockwise, then around B clockwise, north through the middle corridor both times
    "figure8": [(12.5, 1.5), (12.5, 12.5), (1.5, 12.5), (1.5, 1.5),
                (12.5, 1.5), (12.5, 12.5), (23.5, 12.5), (23.5, 1.5)],
    # clockwise around block B, as the figure eight drives it: north through the middle corridor
    "laps-b": [(12.5, 1.5), (12.5, 12.5), (23.5, 12.5), (23.5, 1.5)],
}
START_AT = {"laps": 3.0, "figure8": 2.0, "laps-b": 2.0}  # arc length of the start point along the centre line (m)
# 'laps-wide': the laps of block A, every second lap driven 0.45 m to the side with the body
# (and camera) turned 30 deg off the direction of travel, so revisits are wide-baseline:
# lateral offset and a heading difference in the 20-45 deg of loop closure's hard cases
WIDE_OFFSET_M = 0.45
WIDE_YAW_DEG = 30.0
WIDE_RAMP_M = 0.8  # the change of lane and heading is smoothed over about this length (sigma)
KINDS = ("laps", "figure8", "laps-wide", "laps-b")


def _centre_line(waypoints, radius: float):
    """Dense samples (positions, unit tangents, signed curvature) of the filleted closed polyline."""
    P = np.asarray(waypoints, dtype=np.float64)
    n = len(P)
    pts, tans, curv = [], [], []
    # tangent points of each corner's fillet
    fillets = []
    for i in range(n):
        a, b, c = P[i - 1], P[i], P[(i + 1) % n]
        d_in = (b - a) / np.linalg.norm(b - a)
        d_out = (c - b) / np.linalg.norm(c - b)
        turn = np.arctan2(d_in[0] * d_out[1] - d_in[1] * d_out[0], d_in @ d_out)  # +left
        k = radius * np.tan(abs(turn) / 2.0)
        left = np.array([-d_in[1], d_in[0]])
        centre = b - d_in * k + np.sign(turn) * left * radius
        fillets.append((b - d_in * k, b + d_out * k, centre, turn))
    for i in range(n):
        _, t_out, _, _ = fillets[i]
        t_in_next, _, centre, turn = fillets[(i + 1) % n]
        # straight from the end of fillet i to the start of fillet i+1
        seg = t_in_next - t_out
        L = np.linalg.norm(seg)
        m = max(1, int(np.ceil(L / STEP)))
        s = np.arange(m) / m
        pts.append(t_out + s[:, None] * seg)
        tans.append(np.repeat((seg / L)[None], m, axis=0))
        curv.append(np.zeros(m))
        # arc around corner i+1
        a0 = np.arctan2(t_in_next[1] - centre[1], t_in_next[0] - centre[0])
        arc_len = radius * abs(turn)
        m = max(1, int(np.ceil(arc_len / STEP)))
        ang = a0 + turn * np.arange(m) / m
        pts.append(centre + radius * np.column_stack([np.cos(ang), np.sin(ang)]))
        sgn = np.sign(turn)
        tans.append(np.column_stack([-np.sin(ang) * sgn, np.cos(ang) * sgn]))
        curv.append(np.full(m, sgn / radius))
    pos = np.concatenate(pts)
    tan = np.concatenate(tans)
    kappa = np.concatenate(curv)
    seglen = np.linalg.norm(np.diff(np.vstack([pos, pos[:1]]), axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seglen)[:-1]])
    return pos, tan, kappa, s, float(seglen.sum())


@dataclass
class DemoPath:
    """A continuous-time robot path: body poses at any time, lap counter, length."""

    kind: str
    times: np.ndarray  # (M,) seconds since start, dense (1 cm of travel apart)
    xy: np.ndarray  # (M, 2)
    yaw: np.ndarray  # (M,) unwrapped
    distance: np.ndarray  # (M,) distance travelled along the centre line
    lap_length: float

    @property
    def duration_s(self) -> float:
        return float(self.times[-1])

    def _interp(self, t):
        t = np.clip(np.asarray(t, dtype=np.float64), 0.0, self.times[-1])
        x = np.interp(t, self.times, self.xy[:, 0])
        y = np.interp(t, self.times, self.xy[:, 1])
        yaw = np.interp(t, self.times, self.yaw)
        return x, y, yaw

    def pose_at(self, t) -> np.ndarray:
        """Body poses ``T_world_body`` (N, 4, 4) at times ``t`` (seconds since start)."""
        x, y, yaw = self._interp(np.atleast_1d(t))
        T = np.repeat(np.eye(4)[None], len(x), axis=0)
        c, s = np.cos(yaw), np.sin(yaw)
        T[:, 0, 0], T[:, 0, 1], T[:, 1, 0], T[:, 1, 1] = c, -s, s, c
        T[:, 0, 3], T[:, 1, 3] = x, y
        return T

    def laps_at(self, t) -> np.ndarray:
        """Laps completed (fractional) at times ``t``; the lighting epoch of the renderer."""
        t = np.clip(np.asarray(t, dtype=np.float64), 0.0, self.times[-1])
        return np.interp(t, self.times, self.distance) / self.lap_length


def make_path(kind: str = "laps", laps: float = 2.0, seed: int = 0, speed: float = 1.1,
              turn_speed: float = 0.7, weave: float = 0.18, start_at: float | None = None) -> DemoPath:
    """Build the continuous path for ``laps`` laps of ``kind`` ('laps', 'figure8', 'laps-wide' or 'laps-b').

    ``start_at``: arc length (m) of the start point along the route's centre line, measured
    from the centre line's origin (:data:`START_AT` holds each route's default; values wrap
    around the lap). The weave, the speed ramp and the lap counter run from the start point.
    """
    if kind not in KINDS:
        raise ValueError(f"unknown trajectory kind {kind!r}; use one of {list(KINDS)}")
    wide = kind == "laps-wide"
    kind_path = "laps" if wide else kind
    if not laps > 0:
        raise ValueError("laps must be positive")
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0x7EA7]))
    pos, tan, kappa, s_c, L = _centre_line(WAYPOINTS[kind_path], TURN_RADIUS)
    total = laps * L
    S = np.arange(0.0, total + STEP, STEP)
    s0 = START_AT[kind_path] if start_at is None else float(start_at)
    if not np.isfinite(s0):
        raise ValueError("start_at must be a finite arc length (m)")
    s_mod = np.mod(S + s0, L)
    idx = np.searchsorted(s_c, s_mod, side="right") - 1
    c = pos[idx] + tan[idx] * (s_mod - s_c[idx])[:, None]
    left = np.column_stack([-tan[idx, 1], tan[idx, 0]])
    ph = rng.uniform(0, 2 * np.pi, size=2)
    offset = weave * np.sin(2 * np.pi * S / 9.7 + ph[0]) + 0.6 * weave * np.sin(2 * np.pi * S / 23.3 + ph[1])
    side = np.zeros_like(S)
    if wide:  # 0 on even laps, 1 on odd ones, smoothed
        square = (np.floor(S / L) % 2 == 1).astype(np.float64)
        sw = int(WIDE_RAMP_M / STEP)
        kw = np.exp(-0.5 * (np.arange(-3 * sw, 3 * sw + 1) / sw) ** 2)
        side = np.convolve(np.pad(square, 3 * sw, mode="edge"), kw / kw.sum(), mode="valid")
        offset = offset + WIDE_OFFSET_M * side
    xy = c + offset[:, None] * left
    d = np.gradient(xy, axis=0)
    yaw = np.unwrap(np.arctan2(d[:, 1], d[:, 0])) + np.radians(WIDE_YAW_DEG) * side
    # speed: slow in turns (curvature smoothed over ~0.8 m), ramp up over the first 1.5 m
    k = np.abs(kappa[idx]) * TURN_RADIUS
    sig = int(0.8 / STEP)
    ker = np.exp(-0.5 * (np.arange(-3 * sig, 3 * sig + 1) / sig) ** 2)
    ker /= ker.sum()
    k = np.convolve(np.pad(k, 3 * sig, mode="edge"), ker, mode="valid")
    k = np.clip(k, 0.0, 1.0)
    v = speed - (speed - turn_speed) * k
    v *= np.minimum(1.0, 0.3 + 0.7 * S / 1.5)
    ds = np.linalg.norm(np.diff(xy, axis=0), axis=1)
    dt = ds / (0.5 * (v[1:] + v[:-1]))
    times = np.concatenate([[0.0], np.cumsum(dt)])
    return DemoPath(kind=kind, times=times, xy=xy, yaw=yaw, distance=S, lap_length=L)


def sample_stamps(duration_s: float, rate_hz: float, start_ns: int = START_NS) -> np.ndarray:
    """Stamps (int ns) at an exact rate from ``start_ns`` to ``duration_s`` inclusive."""
    period_ns = int(round(1e9 / rate_hz))
    n = int(np.floor(duration_s * 1e9 / period_ns + 1e-9)) + 1
    return start_ns + period_ns * np.arange(n, dtype=np.int64)


def path_trajectory(path: DemoPath, stamps: np.ndarray, start_ns: int = START_NS) -> Trajectory:
    """Ground-truth body trajectory of ``path`` at ``stamps`` (frame 'world', child 'base_link')."""
    t = (np.asarray(stamps, dtype=np.int64) - start_ns) * 1e-9
    return Trajectory(stamps=stamps, poses=path.pose_at(t), frame_id="world", child_frame_id="base_link")


def make_trajectory(kind: str = "laps", *, laps: float = 2.0, rate_hz: float = 10.0, seed: int = 0,
                    start_ns: int = START_NS, frames: int | None = None, start_at: float | None = None) -> Trajectory:
    """Ground-truth body poses at ``rate_hz`` for ``laps`` laps (or exactly ``frames`` samples).

    With ``frames`` the path is made long enough and cut after ``frames`` samples.
    ``start_at``: the start point's arc length along the centre line (see :func:`make_path`).
    """
    if frames is not None:
        if frames < 1:
            raise ValueError("frames must be at least 1")
        need_s = (frames - 1) / rate_hz
        path = make_path(kind, laps=laps, seed=seed, start_at=start_at)
        while path.duration_s < need_s:
            path = make_path(kind, laps=path.distance[-1] / path.lap_length * (need_s / path.duration_s) * 1.05 + 0.05,
                             seed=seed, start_at=start_at)
        stamps = start_ns + int(round(1e9 / rate_hz)) * np.arange(frames, dtype=np.int64)
        return path_trajectory(path, stamps, start_ns)
    path = make_path(kind, laps=laps, seed=seed, start_at=start_at)
    return path_trajectory(path, sample_stamps(path.duration_s, rate_hz, start_ns), start_ns)
