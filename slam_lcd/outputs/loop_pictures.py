"""Per-loop pictures under ``loops/`` (the paper's Fig. 1) and a contact sheet of the accepted loops.

Why this way: at output time the run has dropped every image, and the loop detector's
records keep figures, not per-match arrays (memory per keyframe stays small).
The cheapest honest source is a :class:`KeyframeAlbum` filled while the run goes: each
keyframe's image (JPEG), keypoints and descriptors (in the detector's stored precision)
go to a working folder on disk as the keyframe leaves loop detection, so memory stays
bounded. Each loop the detector hands on also leaves its verified matches and the rows
its graph kept there (:meth:`KeyframeAlbum.keep_loop`, a few kB), so its picture shows
exactly what was verified and costs no second verification at output time. For the
detector-rejected candidates that are drawn, the one-to-one matches, the verification
budget and the graph verification are recomputed with the loop detector's own functions
and settings (they are deterministic), and the picture says so when the recomputed
figures differ from the run's record. The album costs about as much disk as the
detector's descriptor store and is removed when the outputs are written.

Drawn: every loop the back end accepted, every loop it rejected, and the
``run.loop_pictures_rejected`` detector-rejected candidates that came closest (most
graph nodes, then most matches), each with its verdict and reason.
"""
from __future__ import annotations

import logging
import shutil
from pathlib import Path

import cv2
import numpy as np

from ..backend.pose_graph import ACCEPTED
from ..features.matching import mutual_nn_match_bf
from ..lcd.budget import select_matches
from ..lcd.graph import planar_graph, verify_graph
from ..lcd.store import compact_descriptors

log = logging.getLogger(__name__)

LOOPS_DIR = "loops"
CONTACT_SHEET = "contact_sheet.jpg"
ALBUM_MAX_WIDTH = 640  # stored images are scaled down to this width (keypoints are scaled alike)
# The pictures are JPEG with full-resolution colour (4:4:4): a camera image under thin drawn lines
# codes in ~4 ms (PNG: ~19 ms) into ~0.4 MB (PNG: ~1 MB), and without chroma subsampling the
# lines keep their colour (99% of the green pixels; 4:2:0 kept 46-71%). 3,000 loops of an
# hour-long log are then ~1.6 GB less disk and ~45 s less CPU.
PICTURE_JPEG = [cv2.IMWRITE_JPEG_QUALITY, 90, cv2.IMWRITE_JPEG_SAMPLING_FACTOR, cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444]
PICTURE_THREADS = 2  # pictures made at a time (write_loop_pictures)
CONTACT_TILE_WIDTH = 360
CONTACT_SHEET_MAX = 120  # tiles on the contact sheet at most (evenly spread over the accepted loops)


class KeyframeAlbum:
    """Keyframe images, keypoints and descriptors on disk (see the module docstring)."""

    def __init__(self, folder: Path, descriptor_dtype: str = "float16"):
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.descriptor_dtype = descriptor_dtype
        self.ids: set[int] = set()
        self.failed: str | None = None  # why keyframes stopped being kept (e.g. a full disk)

    def __call__(self, kf) -> None:
        """Keep keyframe ``kf`` (the pipeline calls this before it drops the keyframe's image).

        A write error stops the album (one warning, at output time): pictures are a nicety,
        the run goes on."""
        if kf.image is None or kf.features is None or self.failed is not None:
            return
        try:
            self._keep(kf)
        except OSError as e:
            self.failed = f"keyframe {kf.id}: {e.strerror or e}"
            log.info("loop pictures: keyframes no longer kept (%s)", self.failed)

    def _keep(self, kf) -> None:
        img = np.asarray(kf.image)
        if img.dtype != np.uint8:
            img = np.clip(img * (255.0 if img.max() <= 1.0 else 1.0), 0, 255).astype(np.uint8)
        scale = min(1.0, ALBUM_MAX_WIDTH / img.shape[1])
        if scale < 1.0:
            img = cv2.resize(img, (round(img.shape[1] * scale), round(img.shape[0] * scale)),
                             interpolation=cv2.INTER_AREA)
        if not cv2.imwrite(str(self.folder / f"{kf.id}.jpg"), img, [cv2.IMWRITE_JPEG_QUALITY, 90]):
            raise OSError(f"cannot write {self.folder / f'{kf.id}.jpg'}")
        f = kf.features
        np.savez(self.folder / f"{kf.id}.npz", keypoints=np.asarray(f.keypoints, np.float32),
                 descriptors=compact_descriptors(f.descriptors, self.descriptor_dtype),
                 image_size=np.asarray(f.image_size, np.int64), scale=np.float64(scale))
        self.ids.add(int(kf.id))

    def keep_loop(self, rec) -> None:
        """Keep a loop's verified matches and the graph's kept rows (the detector calls this before it drops them)."""
        if rec.graph_matches is None or rec.graph is None or self.failed is not None:
            return
        try:
            np.savez(self.folder / f"pair_{int(rec.query_id)}_{int(rec.match_id)}.npz",
                     matches=np.asarray(rec.graph_matches, np.int32), kept=np.asarray(rec.graph.kept, np.int32),
                     n_matches=np.int64(rec.n_matches), graph_nodes=np.int64(rec.graph.n_nodes))
        except OSError as e:
            self.failed = f"loop {rec.query_id}-{rec.match_id}: {e.strerror or e}"
            log.info("loop pictures: keyframes no longer kept (%s)", self.failed)

    def load_loop(self, query_id: int, match_id: int):
        """(matches, kept, n_matches, graph nodes) kept by :meth:`keep_loop`, or None."""
        p = self.folder / f"pair_{int(query_id)}_{int(match_id)}.npz"
        if not p.is_file():
            return None
        with np.load(p, allow_pickle=False) as z:
            return (z["matches"].astype(np.int64), z["kept"].astype(np.int64), int(z["n_matches"]),
                    int(z["graph_nodes"]))

    def load(self, kf_id: int):
        """(image, keypoints in the stored image's pixels, descriptors, features image size) or None."""
        if kf_id not in self.ids:
            return None
        img = cv2.imread(str(self.folder / f"{kf_id}.jpg"), cv2.IMREAD_GRAYSCALE)
        with np.load(self.folder / f"{kf_id}.npz", allow_pickle=False) as z:
            return img, z["keypoints"], z["descriptors"], tuple(int(v) for v in z["image_size"]), float(z["scale"])

    def close(self) -> None:
        shutil.rmtree(self.folder, ignore_errors=True)


def picture_name(query_id: int, match_id: int, verdict: str) -> str:
    """``loops/<name>``: one name per (query, match) and verdict ('accepted' / 'rejected')."""
    return f"loop_q{int(query_id):05d}_m{int(match_id):05d}_{verdict}.jpg"


def _graph_edges(kq: np.ndarray, matches: np.ndarray, kept: np.ndarray, conf) -> np.ndarray:
    if len(kept) < 3:
        return np.zeros((0, 2), np.int64)
    return planar_graph(kq[matches[kept, 0]].astype(np.float64), conf.graph_max_edge_factor)[1]


def _loop_arrays(rec_row: dict, q, m, conf, album: KeyframeAlbum):
    """Matches, kept rows and graph edges: as the detector kept them for its loops, else recomputed."""
    kept_loop = album.load_loop(int(rec_row["query_id"]), int(rec_row["match_id"]))
    if kept_loop is None:
        return _recompute(rec_row, q, m, conf)
    matches, kept, _, _ = kept_loop
    return matches, kept, _graph_edges(q[1], matches, kept, conf), []


def _recompute(rec_row: dict, q, m, conf):
    """Matches, the rows the graph kept and the graph's edges, recomputed as the detector computes them
    (for candidates the detector rejected, whose arrays it did not hand on)."""
    _, kq, dq, size_q, _ = q
    _, km, dm, _, _ = m
    binary = dq.dtype == np.uint8
    max_d = conf.match_max_distance_orb if binary else conf.match_max_distance_sp
    matches, dist = mutual_nn_match_bf(dq, dm, ratio=conf.match_ratio, max_distance=max_d, return_distances=True)
    n_found = len(matches)
    if 0 < conf.verify_max_matches < len(matches):
        matches = matches[select_matches(matches, dist, kq, conf.verify_max_matches, size_q, conf.verify_spread_cells)]
    g = verify_graph(kq, km, matches, conf) if len(matches) else None
    kept = np.asarray(g.kept, np.int64) if g is not None else np.zeros(0, np.int64)
    edges = _graph_edges(kq, matches, kept, conf)
    notes = []
    if str(rec_row.get("n_matches", "")) not in ("", str(n_found)):
        notes.append(f"recomputed {n_found} matches (run: {rec_row['n_matches']})")
    if g is not None and str(rec_row.get("graph_nodes", "")) not in ("", str(g.n_nodes)):
        notes.append(f"recomputed {g.n_nodes} graph nodes (run: {rec_row['graph_nodes']})")
    return matches, kept, edges, notes


def _segments(img: np.ndarray, a: np.ndarray, b: np.ndarray, colour) -> None:
    """Anti-aliased 1-px segments a[i]-b[i], in one call (per-segment calls cost more in Python than in drawing)."""
    if len(a):
        pts = np.stack([np.round(a), np.round(b)], axis=1).astype(np.int32)  # (n, 2, 2)
        cv2.polylines(img, list(pts), False, colour, 1, cv2.LINE_AA)


# a filled dot of radius 2: the 5x5 square without its corners
_DOT = np.array([(dy, dx) for dy in range(-2, 3) for dx in range(-2, 3) if dy * dy + dx * dx <= 5])


def _dots(img: np.ndarray, pts: np.ndarray, colour) -> None:
    """Filled dots at ``pts`` (x, y) in one indexed write (a circle call per point cost ~3 ms a picture)."""
    if not len(pts):
        return
    p = np.round(pts).astype(np.int64)
    ys = (p[:, 1, None] + _DOT[None, :, 0]).ravel()
    xs = (p[:, 0, None] + _DOT[None, :, 1]).ravel()
    inside = (ys >= 0) & (ys < img.shape[0]) & (xs >= 0) & (xs < img.shape[1])
    img[ys[inside], xs[inside]] = colour


def draw_loop(q, m, matches, kept, edges, lines: list[str], colour: tuple[int, int, int]) -> np.ndarray:
    """Query (left) and match (right) side by side: discarded matches thin red, surviving matches
    green, the graph on the surviving query keypoints and the same edges on their matches (yellow)."""
    img_q, kq, _, _, sq = q
    img_m, km, _, _, sm = m
    h = max(img_q.shape[0], img_m.shape[0])
    canvas = np.full((h, img_q.shape[1] + img_m.shape[1], 3), 0, np.uint8)
    canvas[:img_q.shape[0], :img_q.shape[1]] = cv2.cvtColor(img_q, cv2.COLOR_GRAY2BGR)
    canvas[:img_m.shape[0], img_q.shape[1]:] = cv2.cvtColor(img_m, cv2.COLOR_GRAY2BGR)
    off = np.array([img_q.shape[1], 0.0])
    pq = kq[matches[:, 0]] * sq if len(matches) else np.zeros((0, 2))
    pm = km[matches[:, 1]] * sm + off if len(matches) else np.zeros((0, 2))
    survived = np.zeros(len(matches), bool)
    survived[kept] = True
    overlay = canvas.copy()
    _segments(overlay, pq[~survived], pm[~survived], (60, 60, 220))
    canvas = cv2.addWeighted(overlay, 0.5, canvas, 0.5, 0)
    gq, gm = pq[kept], pm[kept]
    if len(edges):
        for P in (gq, gm):
            _segments(canvas, P[edges[:, 0]], P[edges[:, 1]], (0, 220, 255))
    _segments(canvas, gq, gm, (80, 200, 80))
    _dots(canvas, np.concatenate([gq, gm]), (80, 255, 80))
    per_line = max(20, (canvas.shape[1] - 20) // 8)  # characters that fit at this font size
    lines = [ln[i:i + per_line] for ln in lines for i in range(0, max(len(ln), 1), per_line)]
    band = np.full((18 * len(lines) + 8, canvas.shape[1], 3), 255, np.uint8)
    cv2.rectangle(band, (0, 0), (8, band.shape[0]), colour, -1)
    for k, text in enumerate(lines):
        cv2.putText(band, text, (14, 18 * (k + 1)), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (20, 20, 20), 1, cv2.LINE_AA)
    return np.vstack([band, canvas])


def _pictured(rows: list[dict], n_rejected: int) -> list[tuple[dict, str]]:
    """(row, 'accepted'/'rejected') of the candidates to draw (see the module docstring)."""
    chosen = [(r, "accepted") for r in rows if r["backend_verdict"] == ACCEPTED]
    chosen += [(r, "rejected") for r in rows if r["backend_verdict"] not in ("", ACCEPTED)]

    def closeness(r):  # failures of a check first (not 'not_best' / 'temporal_pending'), then the closest
        failed = r["reason"].split(":")[0] in ("graph", "ransac", "pose")
        return (failed, int(r["graph_nodes"] or 0), int(r["n_matches"] or 0))

    near = sorted((r for r in rows if not r["backend_verdict"] and int(r["n_matches"] or 0) > 0),
                  key=closeness, reverse=True)
    seen = {(r["query_id"], r["match_id"]) for r, _ in chosen}
    for r in near:
        if n_rejected <= 0:
            break
        if (r["query_id"], r["match_id"]) not in seen:
            seen.add((r["query_id"], r["match_id"]))
            chosen.append((r, "rejected"))
            n_rejected -= 1
    return chosen


def _caption(row: dict, verdict: str) -> list[str]:
    lines = [f"query {row['query_id']} <-> match {row['match_id']}: {verdict.upper()}"
             + (f" by the back end ({row['backend_reason']})" if row["backend_verdict"] else
                f" by the detector ({row['reason']})")]
    lines.append(f"BoW rank {row['rank']} score {row['bow_score']}, {row['n_matches']} matches, "
                 f"graph nodes {row['graph_nodes'] or '-'}, pose inliers {row['pose_inliers'] or '-'}")
    if row["gt_distance_m"] != "":
        lines.append(f"ground truth: keyframes {float(row['gt_distance_m']):.2f} m apart"
                     + (f", loop pose error {float(row['err_trans_m']):.3f} m"
                        + (f" / {float(row['err_rot_deg']):.2f} deg" if row["err_rot_deg"] != "" else "")
                        if row["err_trans_m"] != "" else ""))
    return lines


def write_loop_pictures(out_dir: Path, album: KeyframeAlbum, rows: list[dict], lcd_conf,
                        n_rejected: int, stop=None, thumbnails: dict | None = None,
                        thumb_width: int = 240) -> list[str]:
    """Draw the chosen loops into ``out_dir/loops``; returns the picture names written (contact sheet last).

    ``stop``: a :class:`threading.Event` checked before each picture (the outputs are being abandoned).
    ``thumbnails``: filled with ``name -> JPEG bytes`` of each picture scaled to ``thumb_width`` (the
    HTML report's table embeds them without decoding the picture again).

    Two pictures are made at a time, each in a thread of its own: reading the album, drawing
    and the JPEG coding (~4 ms a picture) run mostly outside the GIL. They are listed in the
    order they are chosen. The contact sheet keeps a small tile per accepted loop, not the
    picture, and shows at most :data:`CONTACT_SHEET_MAX` of them, evenly spread: an hour-long
    log has thousands of loops."""
    from concurrent.futures import ThreadPoolExecutor

    folder = out_dir / LOOPS_DIR
    folder.mkdir(exist_ok=True)
    written, tiles, missing = [], [], 0
    pending: list = []

    def collect(future) -> None:
        nonlocal missing
        made = future.result()  # a write error surfaces here
        if made is None:
            missing += 1  # a keyframe the album did not keep (a write error, an interrupt mid-keyframe)
            return
        name, verdict, tile, thumb = made
        written.append(name)
        if thumbnails is not None and thumb is not None:
            thumbnails[name] = thumb
        if verdict == "accepted":
            tiles.append(tile)

    with ThreadPoolExecutor(max_workers=PICTURE_THREADS, thread_name_prefix="slam-lcd-pictures") as pool:
        try:
            for row, verdict in _pictured(rows, n_rejected):
                if stop is not None and stop.is_set():
                    return written
                pending.append(pool.submit(_make_picture, folder, album, row, verdict, lcd_conf,
                                           thumb_width if thumbnails is not None else 0))
                while len(pending) > 2 * PICTURE_THREADS:  # a few pictures in memory at most
                    collect(pending.pop(0))
        finally:
            for future in pending:  # the pictures already started are finished (and listed) first
                collect(future)
    if tiles:
        if len(tiles) > CONTACT_SHEET_MAX:
            tiles = [tiles[i] for i in np.linspace(0, len(tiles) - 1, CONTACT_SHEET_MAX).round().astype(int)]
        _write_picture(folder / CONTACT_SHEET, contact_sheet(tiles, CONTACT_TILE_WIDTH))
        written.append(CONTACT_SHEET)
    if missing and album.failed:
        log.warning("loop pictures: %d loop(s) not drawn, their keyframes were not kept (%s)", missing, album.failed)
    if not written:
        folder.rmdir()
    return written


def _make_picture(folder: Path, album: KeyframeAlbum, row: dict, verdict: str, lcd_conf, thumb_width: int):
    """One loop's picture written to ``folder``: (name, verdict, contact-sheet tile, JPEG thumbnail or None),
    or None when the album lacks one of its keyframes."""
    q, m = album.load(int(row["query_id"])), album.load(int(row["match_id"]))
    if q is None or m is None:
        return None
    matches, kept, edges, notes = _loop_arrays(row, q, m, lcd_conf, album)
    colour = (60, 170, 60) if verdict == "accepted" else (60, 60, 200)
    pic = draw_loop(q, m, matches, kept, edges, _caption(row, verdict) + notes, colour)
    name = picture_name(row["query_id"], row["match_id"], verdict)
    _write_picture(folder / name, pic)
    tile = _scaled(pic, CONTACT_TILE_WIDTH)
    thumb = None
    if thumb_width:
        ok, buf = cv2.imencode(".jpg", _scaled(tile, thumb_width), [cv2.IMWRITE_JPEG_QUALITY, 80])
        thumb = buf.tobytes() if ok else None
    return name, verdict, tile, thumb


def _scaled(img: np.ndarray, width: int) -> np.ndarray:
    """``img`` scaled to ``width`` by area averaging, halved first while it stays at least twice as wide.

    Why: OpenCV's area averaging has a fast path for whole-number factors only; 1280 -> 360 px took
    1.7 ms a picture, 1280 -> 640 -> 360 takes ~0.9 ms (each output pixel is still the mean of the
    source pixels it covers, up to the rounding of the intermediate image)."""
    size = (width, max(1, round(img.shape[0] * width / img.shape[1])))
    while img.shape[1] >= 2 * width and img.shape[0] >= 2 * size[1]:
        img = cv2.resize(img, (img.shape[1] // 2, img.shape[0] // 2), interpolation=cv2.INTER_AREA)
    return cv2.resize(img, size, interpolation=cv2.INTER_AREA)


def _write_picture(path: Path, img: np.ndarray) -> None:
    if not cv2.imwrite(str(path), img, PICTURE_JPEG):
        raise OSError(f"cannot write {path}")


def contact_sheet(pictures: list[np.ndarray], width: int = CONTACT_TILE_WIDTH, columns: int = 4) -> np.ndarray:
    """The pictures scaled to ``width`` (unless they are that wide) and tiled ``columns`` to a row (white gaps)."""
    tiles = [p if p.shape[1] == width else _scaled(p, width) for p in pictures]
    h = max(t.shape[0] for t in tiles)
    rows = []
    for i in range(0, len(tiles), columns):
        row = [np.pad(t, ((0, h - t.shape[0]), (4, 4), (0, 0)), constant_values=255) for t in tiles[i:i + columns]]
        row += [np.full((h, width + 8, 3), 255, np.uint8)] * (columns - len(row))
        rows.append(np.pad(np.hstack(row), ((4, 4), (0, 0), (0, 0)), constant_values=255))
    return np.vstack(rows)
