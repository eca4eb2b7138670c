"""Loop-closure evaluation: ground truth loading, precision-recall, recall at 100% precision.

Protocol (documented in docs/lcd.md):
- every query keyframe yields at most one detection: among its BoW candidates that pass the
  verification mode, the one with the most verified correspondences (graph nodes, RANSAC
  inliers; for BoW only: the highest BoW score); its score is its BoW score;
- a detection is a true positive when the ground truth marks (query, match) as a loop;
- the positives are the queries that have at least one ground-truth loop with a keyframe
  old enough to be a candidate (outside the excluded recent window);
- the precision-recall curve sweeps a threshold over the detection scores; recall at 100%
  precision is the largest recall whose precision is exactly 1; the area under the curve is
  the average precision (sum over thresholds of precision x recall gained), 1 for a
  detector that finds every positive before its first false detection;
- Recall@N of retrieval (the VPR measure): the share of the positives whose N best BoW
  candidates include a true loop (before any verification);
- with ground-truth poses, recall per revisit *place*: the positives are cut into places
  (a run of consecutive positive keyframes, a new place every ``place_size_m`` of travel)
  and a place is found when one of its keyframes has a true detection.
"""
from __future__ import annotations

import csv
import io
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import FileMissingError, InputError, UnsupportedFormatError
from ..files.atomic import atomic_path, write_text
from ..files.image_files import IMAGE_SUFFIXES, read_image
from ..lcd.detector import CandidateRecord

# ----------------------------------------------------------------------------- ground truth


def load_loop_matrix(path: str | Path, names: Sequence[str]) -> np.ndarray:
    """Ground-truth loop matrix (N, N) bool, ``gt[i, j]`` = keyframe i closes a loop with keyframe j.

    Formats: an image (RTAB-Map ``samples_GT.bmp`` style, non-zero = loop), ``.npy`` (bool or
    0/1 matrix), ``.csv``/``.txt`` pairs ``query,match`` given as file stems of ``names`` or as
    0-based indices. The matrix is made symmetric.
    """
    path = Path(path)
    if not path.is_file():
        raise FileMissingError("ground-truth file not found (--gt)", path)
    n = len(names)
    suffix = path.suffix.lower()
    if suffix in IMAGE_SUFFIXES:
        import cv2

        try:
            img = read_image(path, cv2.IMREAD_GRAYSCALE)
        except InputError as e:
            raise UnsupportedFormatError(f"ground-truth image: {e.problem}", path) from None
        gt = img > 127
    elif suffix == ".npy":
        try:
            gt = np.load(path, allow_pickle=False)
        except (ValueError, OSError) as e:
            raise UnsupportedFormatError(f"not a readable .npy matrix ({e.__class__.__name__})", path) from None
        if gt.ndim != 2:
            raise InputError(f"ground-truth matrix must be 2-D, got shape {gt.shape}", path)
        gt = gt.astype(bool)
    elif suffix in (".csv", ".txt"):
        gt = np.zeros((n, n), bool)
        stems = {Path(s).stem: k for k, s in enumerate(names)}
        text = path.read_text(encoding="utf-8", errors="replace")
        for line_no, row in enumerate(csv.reader(io.StringIO(text.replace(" ", ","))), 1):
            row = [c for c in row if c.strip()]
            if not row or row[0].startswith("#"):
                continue
            if len(row) < 2:
                raise InputError(f"line {line_no}: expected 'query,match'", path)
            ij: list[int] | None  # None: a token is neither a stem nor an index
            ij = []
            for tok in row[:2]:
                tok = tok.strip()
                if tok in stems:
                    ij.append(stems[tok])
                elif re.fullmatch(r"\d+", tok):
                    ij.append(int(tok))
                else:
                    ij = None
                    break
            if ij is None:
                if line_no == 1:
                    continue  # header
                raise InputError(f"line {line_no}: {row[:2]} are neither file stems nor indices", path)
            i, j = ij
            if not (0 <= i < n and 0 <= j < n):
                raise InputError(f"line {line_no}: index out of range for {n} images", path)
            gt[i, j] = True
    else:
        raise UnsupportedFormatError("ground truth must be an image (.bmp/.png), .npy or .csv pairs", path)
    if gt.shape != (n, n):
        raise InputError(f"ground-truth matrix is {gt.shape[0]}x{gt.shape[1]} but there are {n} images", path)
    return gt | gt.T


def loops_from_poses(poses: np.ndarray, max_dist: float, max_angle_deg: float) -> np.ndarray:
    """Loop matrix from ground-truth poses (N, 4, 4): closer than ``max_dist`` metres and ``max_angle_deg``."""
    p = poses[:, :3, 3]
    d = np.linalg.norm(p[:, None] - p[None], axis=2)
    R = poses[:, :3, :3]
    tr = np.einsum("iab,jab->ij", R, R)  # trace(Ri^T Rj)
    ang = np.degrees(np.arccos(np.clip((tr - 1) / 2, -1, 1)))
    gt = (d <= max_dist) & (ang <= max_angle_deg)
    np.fill_diagonal(gt, False)
    return gt


# ----------------------------------------------------------------------------- metrics


@dataclass
class PRResult:
    mode: str
    precision: np.ndarray  # at each threshold (detections sorted by score, best first)
    recall: np.ndarray
    thresholds: np.ndarray
    recall_at_100p: float
    precision_all: float  # precision of every detection (the detector's own operating point)
    recall_all: float
    n_detections: int
    n_true: int
    n_positives: int
    auc: float = 0.0  # area under the PR curve (average precision)

    def summary(self) -> dict:
        return {
            "mode": self.mode,
            "recall_at_100_precision": round(self.recall_at_100p, 4),
            "pr_auc": round(self.auc, 4),
            "precision": round(self.precision_all, 4),
            "recall": round(self.recall_all, 4),
            "detections": self.n_detections,
            "true_detections": self.n_true,
            "positives": self.n_positives,
        }


def detections(records: Iterable[CandidateRecord], mode: str) -> dict[int, CandidateRecord]:
    """Per query, the candidate passing ``mode`` with the most verified correspondences (as the detector picks)."""
    best: dict[int, CandidateRecord] = {}
    for r in records:
        if r.reason == "low_bow_score" or not r.passes(mode):
            continue
        b = best.get(r.query_id)
        if b is None or (r.support(mode), r.bow_score) > (b.support(mode), b.bow_score):
            best[r.query_id] = r
    return best


def positives(gt: np.ndarray, exclude_recent_n: int) -> np.ndarray:
    """Queries (positions) having a ground-truth loop with an older keyframe outside the recent window."""
    n = len(gt)
    pos = np.zeros(n, bool)
    for i in range(n):
        upto = i - max(exclude_recent_n, 0)
        if upto > 0:
            pos[i] = bool(gt[i, :upto].any())
    return pos


def precision_recall(records: Sequence[CandidateRecord], gt: np.ndarray, mode: str, exclude_recent_n: int) -> PRResult:
    """PR curve of ``mode`` over the detections (keyframe ids must be positions 0..N-1 of ``gt``)."""
    det = sorted(detections(records, mode).values(), key=lambda r: -r.bow_score)
    n_pos = int(positives(gt, exclude_recent_n).sum())
    correct = np.array([bool(gt[r.query_id, r.match_id]) for r in det], dtype=bool)
    scores = np.array([r.bow_score for r in det], dtype=np.float64)
    tp = np.cumsum(correct)
    k = np.arange(1, len(det) + 1)
    precision = tp / np.maximum(k, 1)
    recall = tp / max(n_pos, 1)
    # thresholds: only the last detection of a run of equal scores is a valid cut
    valid = np.ones(len(det), bool)
    if len(det) > 1:
        valid[:-1] = scores[:-1] != scores[1:]
    perfect = valid & (precision >= 1.0)
    r100 = float(recall[perfect].max()) if perfect.any() else 0.0
    auc = average_precision(precision[valid], recall[valid])
    return PRResult(
        mode=mode,
        precision=precision[valid],
        recall=recall[valid],
        thresholds=scores[valid],
        recall_at_100p=r100,
        precision_all=float(precision[-1]) if len(det) else 1.0,
        recall_all=float(recall[-1]) if len(det) else 0.0,
        n_detections=len(det),
        n_true=int(correct.sum()),
        n_positives=n_pos,
        auc=auc,
    )


def average_precision(precision: np.ndarray, recall: np.ndarray) -> float:
    """Area under a PR curve given at its thresholds (recall ascending): sum of precision x recall step."""
    if len(recall) == 0:
        return 0.0
    steps = np.diff(np.concatenate([[0.0], np.asarray(recall, np.float64)]))
    return float(np.sum(steps * np.asarray(precision, np.float64)))


def retrieval_recall(retrieved: dict[int, Sequence[int]], gt: np.ndarray, exclude_recent_n: int,
                     ns: Sequence[int] = (1, 5, 10)) -> dict[int, float]:
    """Recall@N of BoW retrieval: share of the positives with a true loop among their N best candidates.

    ``retrieved`` maps a query position to its BoW-ranked candidate positions (the detector's
    ``retrieved`` with ``retrieval_depth >= max(ns)``); a positive absent from it counts as missed.
    """
    pos = np.flatnonzero(positives(gt, exclude_recent_n))
    out = {}
    for n in ns:
        hit = sum(1 for q in pos if any(gt[q, m] for m in list(retrieved.get(int(q), ()))[:n]))
        out[int(n)] = hit / len(pos) if len(pos) else 0.0
    return out


def revisit_places(positions: np.ndarray, gt: np.ndarray, exclude_recent_n: int,
                   place_size_m: float = 1.0) -> list[np.ndarray]:
    """Positive queries grouped into revisit places (see the module note), in keyframe order.

    ``positions`` (N, 3): ground-truth positions of the keyframes. A place is a run of
    consecutive positive keyframes no longer than ``place_size_m`` from its first keyframe.
    """
    pos = np.flatnonzero(positives(gt, exclude_recent_n))
    places: list[list[int]] = []
    for q in pos:
        cur = places[-1] if places else None
        if cur is not None and q == cur[-1] + 1 and \
                np.linalg.norm(positions[q] - positions[cur[0]]) <= place_size_m:
            cur.append(int(q))
        else:
            places.append([int(q)])
    return [np.array(p, np.int64) for p in places]


def place_recall(records: Iterable[CandidateRecord], gt: np.ndarray, mode: str,
                 places: Sequence[np.ndarray]) -> tuple[int, int]:
    """(places found, places): a place is found when one of its keyframes has a true detection under ``mode``."""
    det = detections(records, mode)
    found = 0
    for place in places:
        if any(int(q) in det and gt[int(q), det[int(q)].match_id] for q in place):
            found += 1
    return found, len(places)


# ----------------------------------------------------------------------------- outputs


def format_table(results: Sequence[PRResult], features: str,
                 places: dict[str, tuple[int, int]] | None = None) -> str:
    """One line per mode: R@100P, PR AUC, precision / recall of all detections (and places found)."""
    head = (f"{'features':<11} {'verification':<16} {'R@100P':>7} {'AUC':>6} "
            f"{'precision':>9} {'recall':>7} {'detections':>10}")
    lines = [head + (f" {'places':>8}" if places else "")]
    for r in results:
        label = "BoW only" if r.mode == "none" else f"BoW+{r.mode}"
        line = (f"{features:<11} {label:<16} {r.recall_at_100p:7.3f} {r.auc:6.3f} {r.precision_all:9.3f} "
                f"{r.recall_all:7.3f} {r.n_true:>4}/{r.n_detections:<5}")
        if places and r.mode in places:
            f, n = places[r.mode]
            line += f" {f:>3}/{n:<4}"
        lines.append(line)
    return "\n".join(lines)


def format_retrieval(recall_at: dict[int, float], features: str) -> str:
    """One line: Recall@N of BoW retrieval."""
    return f"{features:<11} retrieval        " + "  ".join(f"R@{n} {v:.3f}" for n, v in sorted(recall_at.items()))


def write_candidates_csv(path: str | Path, records: Sequence[CandidateRecord], gt: np.ndarray | None,
                         names: Sequence[str] | None = None) -> None:
    rows = []
    for r in records:
        row = r.row()
        if names is not None:
            row = {"query": Path(names[r.query_id]).name, "match": Path(names[r.match_id]).name, **row}
        if gt is not None:
            row["gt_loop"] = bool(gt[r.query_id, r.match_id])
        for mode in ("ransac", "graph", "graph+ransac"):
            row[f"pass_{mode}"] = r.passes(mode)
        rows.append(row)
    buf = io.StringIO()
    if rows:
        w = csv.DictWriter(buf, fieldnames=list(rows[0].keys()))
        w.writeheader()
        w.writerows(rows)
    write_text(path, buf.getvalue())


def write_pr_csv(path: str | Path, results: Sequence[PRResult]) -> None:
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(["mode", "threshold", "precision", "recall"])
    for r in results:
        for t, p, rc in zip(r.thresholds, r.precision, r.recall, strict=True):
            w.writerow([r.mode, f"{t:.6f}", f"{p:.6f}", f"{rc:.6f}"])
    write_text(path, buf.getvalue())


def plot_pr(path: str | Path, results: Sequence[PRResult], title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 4.5), dpi=120)
    for r in results:
        if len(r.recall):
            rec = np.concatenate([[0.0], r.recall])
            pre = np.concatenate([[1.0], r.precision])
            ax.plot(rec, pre, marker=".", label=f"{r.mode} (R@100P {r.recall_at_100p:.2f})")
    ax.set_xlabel("recall")
    ax.set_ylabel("precision")
    ax.set_xlim(0, 1.02)
    ax.set_ylim(0, 1.02)
    ax.grid(alpha=0.3)
    ax.set_title(title)
    ax.legend(loc="lower left", fontsize=8)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
