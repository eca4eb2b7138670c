"""Mutual nearest-neighbour matching of unit vectors from a bfloat16 or int8 product, with exact decisions.

Why: growing the online words matches every keyframe's ~1000 descriptors to the previous
keyframe's (and the lost ones to the keyframe before). The float32 product of that match is
~0.5 GFLOP, ~4.8 ms on one core, the largest single step of a keyframe's word search. On CPUs with
AMX or AVX512-BF16 the same product in bfloat16 takes ~0.5 ms, but rounds: inputs to 8 significant
bits, the result to bfloat16. Used naively that would change which descriptors match.

It does not here, because the rounded product only *selects*; every decision is taken on float32
values. For unit vectors a, b with bfloat16 roundings â, b̂ (unit roundoff u = 2^-8),
``|â·b̂ - a·b| <= (2u + u²) Σ|a_i b_i| <= 2u + u²``, the float32 accumulation adds ~256 * 2^-24 and
the bfloat16 result another 2^-9: :data:`ERROR_BOUND` covers all of it with room. A pair can only be
accepted when its similarity exceeds ``s_min = 1 - max_distance² / 2`` (the distance test), so only
the few pairs whose rounded similarity exceeds ``s_min - ERROR_BOUND`` (about one per matched row)
are scored in float32, and the matching rule (mutual nearest neighbours with the lowest index on
ties, ratio and distance tests, as :func:`slam_lcd.vocab.words.mutual_nn_unit`) is applied to them:

- a row's best column passes the distance test only if it is one of its candidates, and then the
  column's best row is among that column's candidates too (it is at least as similar);
- the ratio test needs the second best: a non-candidate is at most ``s_min`` similar, so a row whose
  test is decided by that bound (nearly all: a match is ~0.35 away, the bound is 0.8) needs nothing
  more; the rare row it does not decide gets its whole row in float32.

The answer is therefore the float32 rule's, up to exact ties of float32 values summed in another
order (the product's own rounding differs between BLAS kernels in the same way).

**int8** (:func:`mutual_nn_unit_int8`, ``match_product: int8``, what ``auto`` takes on CPUs with
VNNI or AMX): each image's rows as ``q = rint(s u)`` with one scale ``s = 127 / max |u_i|`` per image;
the integer product is exact, and ``|q1·q2 / (s1 s2) - u1·u2|`` is bounded by the rows' norms of
``q`` and of the rounding residual (:func:`int8_error_bound`: ~0.026 on real SuperPoint images, whose
largest component is ~0.33). The same selection and rule as above follow with that bound; on one
core the int8 product of 1024 x 1024 x 256 takes ~1.4 ms where the bfloat16 one takes ~2.8 ms.
"""
from __future__ import annotations

import contextlib
import functools
import sys
from typing import NamedTuple

import numpy as np

from .descriptors import unit_distance

# bound on |bfloat16 product - exact dot product| for unit vectors: 2u + u² (inputs, u = 2^-8) +
# 2^-9 (the bfloat16 result) + float32 accumulation, rounded up with room for rows a few ulps off unit
ERROR_BOUND = 0.0125
# the similarity threshold (s_min - ERROR_BOUND, below) is positive only for match distances under this
MAX_DISTANCE = 1.4
# rows are padded to a multiple of this (see to_bf16)
_PAD = 128


@functools.lru_cache(maxsize=1)
def bf16_fast() -> bool:
    """True when this CPU multiplies bfloat16 in hardware (AMX or AVX512-BF16): only then is the
    bfloat16 product faster than float32 (emulated, it is slower)."""
    try:
        import torch

        caps = torch.cpu.get_capabilities()
    except Exception:  # noqa: BLE001 - no torch or an older one: the float32 product
        return False
    return bool(caps.get("amx_bf16") or caps.get("avx512_bf16"))


def auto_product() -> str:
    """``match_product: auto``: ``int8`` where the CPU and torch multiply int8 fast (:func:`int8_fast`),
    else ``bfloat16`` where they multiply bfloat16 fast (:func:`bf16_fast`), when torch is already
    loaded; ``float32`` otherwise (an ORB run, a database used on its own: no ~190 MB of torch for one
    product). All three give the same matches."""
    if "torch" not in sys.modules:
        return "float32"
    return "int8" if int8_fast() else ("bfloat16" if bf16_fast() else "float32")


@functools.lru_cache(maxsize=1)
def _openmp():
    """The process's OpenMP runtimes (torch's among them), looked up once; None without threadpoolctl."""
    try:
        from threadpoolctl import ThreadpoolController
    except ImportError:  # pragma: no cover - threadpoolctl is a dependency
        return None
    return ThreadpoolController().select(user_api="openmp")


def one_thread():
    """Context: torch's operations in the calling thread on one OpenMP thread (other threads unchanged).

    Why: these are ~0.5 ms operations; split over two threads they wait for cores that numpy's BLAS
    and faiss workers still spin on, measured 9 ms for a conversion that takes 0.1 ms on one thread.
    ``torch.set_num_threads`` would change every thread (SuperPoint's forward runs in another one);
    OpenMP's thread count set here is the calling thread's own, restored on exit.
    """
    omp = _openmp()
    return omp.limit(limits=1) if omp is not None else contextlib.nullcontext()


def to_bf16(u: np.ndarray):
    """``u`` as a bfloat16 torch tensor of rows (n', D).

    ``n'`` is ``n`` rounded up to a multiple of :data:`_PAD` with zero rows: the CPU kernels are
    compiled per shape (~10 ms each time, more than the product), so shapes must repeat; a zero row's
    products are 0, below every threshold, and never become candidates. The right operand of the
    product is used as a transposed view of its rows: with torch 2.13 that multiplies ~4 % slower
    than a contiguous column copy, and the copy took ~0.27 ms per keyframe.
    """
    import torch

    return _padded(np.ascontiguousarray(u, dtype=np.float32), torch.bfloat16)


def _padded(rows: np.ndarray, dtype):
    """``rows`` as a torch tensor of ``dtype`` with zero rows up to a multiple of :data:`_PAD` (see to_bf16)."""
    import torch

    n = len(rows)
    with one_thread():
        t = torch.zeros((-(-max(n, 1) // _PAD) * _PAD, rows.shape[1]), dtype=dtype)
        t[:n] = torch.from_numpy(rows)
        return t


def _above(buffers: "ProductBuffers", product: np.ndarray, threshold) -> tuple[np.ndarray, np.ndarray]:
    """(rows, cols) of the product's entries above ``threshold``: the candidate pairs."""
    mask = np.greater(product, threshold, out=buffers.mask(product.shape))
    return np.divmod(np.flatnonzero(mask), product.shape[1])


@functools.lru_cache(maxsize=8)
def _threshold(s_min: float) -> tuple[np.int16, float]:
    """The candidate threshold: a bfloat16 value below ``s_min - ERROR_BOUND`` (the spacing below 1 is
    at most 2^-8: room of 0.004), as its int16 bit pattern and its value. Cached: making the torch
    scalar took ~0.1 ms per match."""
    import torch

    thr = torch.tensor(s_min - ERROR_BOUND - 0.004, dtype=torch.float32).to(torch.bfloat16)
    return np.int16(int(thr.view(torch.int16))), float(thr)


class ProductBuffers:
    """The product's output and its threshold mask, kept from one call to the next.

    Why: both are megabytes (1152 x 1152 entries), and a fresh array of that size is new memory
    each time: its first touch faults every page in, which measured longer than the product itself.
    One flat buffer each, grown when needed; a call takes a view of the shape it needs.
    """

    def __init__(self):
        self._outs: dict = {}  # torch dtype -> flat output buffer (bfloat16 product, int32 of the int8 one)
        self._mask = np.empty(0, dtype=bool)

    def _out(self, torch, dtype, rows: int, cols: int):
        buf = self._outs.get(dtype)
        if buf is None or buf.numel() < rows * cols:
            buf = self._outs[dtype] = torch.empty(rows * cols, dtype=dtype)
        return buf[: rows * cols].view(rows, cols)

    def product(self, torch, h1, h2):
        """``h1 @ h2.T`` (both bfloat16 rows) into the kept buffer."""
        return torch.mm(h1, h2.T, out=self._out(torch, torch.bfloat16, h1.shape[0], h2.shape[0]))

    def product_int8(self, torch, q1, q2):
        """``q1 @ q2.T`` (both int8 rows) as int32, into the kept buffer."""
        return torch._int_mm(q1, q2.T, out=self._out(torch, torch.int32, q1.shape[0], q2.shape[0]))

    def mask(self, shape) -> np.ndarray:
        size = shape[0] * shape[1]
        if len(self._mask) < size:
            self._mask = np.empty(size, dtype=bool)
        return self._mask[:size].reshape(shape)


def mutual_nn_unit_bf16(d1: np.ndarray, d2: np.ndarray, ratio: float | None, max_distance: float,
                        h1=None, h2=None, buffers: ProductBuffers | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Matches (row of d1, row of d2) and their distances, as ``mutual_nn_unit(..., return_distances=True)``.

    ``d1``, ``d2``: unit float32 rows; ``h1``, ``h2``: ``to_bf16(d1)`` and ``to_bf16(d2)``
    when the caller has them already; ``buffers``: kept by a caller that matches again and again.
    """
    import torch

    buffers = ProductBuffers() if buffers is None else buffers

    if not max_distance < MAX_DISTANCE:
        raise ValueError(f"mutual_nn_unit_bf16 needs max_distance < {MAX_DISTANCE} (a positive similarity bound)")
    s_min = 1.0 - 0.5 * max_distance * max_distance
    h1 = to_bf16(d1) if h1 is None else h1
    h2 = to_bf16(d2) if h2 is None else h2
    thr_bits, thr = _threshold(s_min)
    # positive bfloat16 values order as their int16 bit patterns, negative ones below every positive
    # pattern: one integer comparison in numpy (torch's bfloat16 comparison and nonzero are ~10x slower)
    with one_thread():
        bits = buffers.product(torch, h1, h2).view(torch.int16).numpy()
    rows, cols = _above(buffers, bits, thr_bits)
    # any pair left out is at most this similar (its rounded product <= thr)
    upper = thr + ERROR_BOUND
    return _decide(d1, d2, rows, cols, upper, ratio, max_distance)


def _decide(d1: np.ndarray, d2: np.ndarray, rows: np.ndarray, cols: np.ndarray, upper: float,
            ratio: float | None, max_distance: float) -> tuple[np.ndarray, np.ndarray]:
    """The matching rule on float32 values, from the candidate pairs (``rows``, ``cols``) of a rounded
    product; ``upper``: the most a pair left out can be similar (see the module doc)."""
    if not len(rows):
        return np.zeros((0, 2), dtype=np.int64), np.zeros(0, np.float32)
    n2 = len(d2)
    sims = np.einsum("ij,ij->i", d1[rows], d2[cols])
    # per row: best first (highest similarity, then lowest column); per column the same by row
    order = np.lexsort((cols, -sims, rows))
    r, c, s = rows[order], cols[order], sims[order]
    first = np.flatnonzero(np.r_[True, r[1:] != r[:-1]])
    counts = np.diff(np.r_[first, len(r)])
    best_r, best_c, best_s = r[first], c[first], s[first]
    second = np.full(len(first), -np.inf, dtype=np.float32)
    has2 = counts > 1  # a second candidate: the second best if it is at least ``upper``
    second[has2] = s[first[has2] + 1]
    corder = np.lexsort((rows, -sims, cols))
    cc, cr = cols[corder], rows[corder]
    cfirst = np.flatnonzero(np.r_[True, cc[1:] != cc[:-1]])
    col_best_row = np.full(n2, -1, dtype=np.int64)
    col_best_row[cc[cfirst]] = cr[cfirst]
    d_best = unit_distance(best_s)
    keep = (d_best < max_distance) & (col_best_row[best_c] == best_r)
    if ratio is not None and n2 > 1:
        # the true second best is max(second, something <= upper): when second >= upper it is the
        # true second and this test is exact; otherwise the test is sure to pass if it passes with
        # upper, and a row for which it does not is decided on its float32 row
        d_sec_known = unit_distance(np.maximum(second, upper))  # smallest the second's distance can be
        ok = d_best < ratio * np.maximum(d_sec_known, 1e-12)
        unsure = keep & (second < upper) & ~ok
        if unsure.any():
            i = best_r[unsure]
            full = d1[i] @ d2.T
            full[np.arange(len(i)), best_c[unsure]] = -np.inf
            ok[unsure] = d_best[unsure] < ratio * np.maximum(unit_distance(full.max(axis=1)), 1e-12)
        keep &= ok
    m = np.stack([best_r[keep], best_c[keep]], axis=1).astype(np.int64)
    return m, d_best[keep].astype(np.float32)


# ------------------------------------------------------------------------------------------ int8
@functools.lru_cache(maxsize=1)
def int8_available() -> bool:
    """True when torch has the int8 product on CPU (``torch._int_mm``, int32 results)."""
    try:
        import torch

        z = torch.zeros((32, 64), dtype=torch.int8)
        torch._int_mm(z, z.T)
    except Exception:  # noqa: BLE001 - no torch, an older one, or no CPU kernel
        return False
    return True


@functools.lru_cache(maxsize=1)
def int8_fast() -> bool:
    """True when this CPU multiplies int8 in hardware (AVX512-VNNI, AVX-VNNI or AMX) and torch has the
    int8 product: there it takes ~1.4 ms for 1024 x 1024 x 256, the bfloat16 product ~2.8 ms (one core
    with AVX512-BF16, torch 2.13)."""
    try:
        import torch

        caps = torch.cpu.get_capabilities()
    except Exception:  # noqa: BLE001 - no torch or an older one: the other products
        return False
    return bool(caps.get("avx512_vnni") or caps.get("avx_vnni") or caps.get("amx_int8")) and int8_available()


class Int8Rows(NamedTuple):
    """Unit rows ``u`` as int8 ``q = rint(scale * u)`` (a torch tensor of ``_PAD``-padded rows), with what
    the error bound needs: ``scale`` (one per image), the largest row norm of ``q`` and of the rounding
    residual ``scale * u - q``."""

    t: object
    scale: float
    q_norm: float
    residual_norm: float


def to_int8(u: np.ndarray) -> Int8Rows:
    """``u`` (unit float32 rows) as :class:`Int8Rows`; the scale maps the image's largest magnitude to 127."""
    u = np.ascontiguousarray(u, dtype=np.float32)
    n = len(u)
    top = max(float(u.max()), -float(u.min())) if n else 1.0
    scale = 127.0 / max(top, 1e-12)
    x = u * np.float32(scale)
    q = np.rint(x)
    x -= q  # the rounding residual
    r_norm = float(np.sqrt(np.einsum("ij,ij->i", x, x).max())) if n else 0.0
    import torch

    t = _padded(q.astype(np.int8), torch.int8)
    # |q| <= |scale u| + |residual|, and the rows are unit (to float32 precision: the 1e-4 of room)
    return Int8Rows(t, scale, scale * (1 + 1e-4) + r_norm, r_norm)


def int8_error_bound(h1: Int8Rows, h2: Int8Rows) -> float:
    """Bound on ``|q1 . q2 / (s1 s2) - u1 . u2|`` for any rows of the two images.

    With ``s u = q + r`` per row: ``s1 s2 u1.u2 - q1.q2 = q1.r2 + r1.q2 + r1.r2``, each term at most
    the product of the two norms (Cauchy-Schwarz); the integer product is exact (|q1.q2| <= 256 *
    127^2 < 2^31). The float32 arithmetic of scaling, rounding and the residuals adds ~1e-5; 1e-4 covers
    it. On real SuperPoint images (scale ~390, residual norms ~5): ~0.026, the actual error ~0.005.
    """
    cross = h1.q_norm * h2.residual_norm + h1.residual_norm * h2.q_norm + h1.residual_norm * h2.residual_norm
    return cross / (h1.scale * h2.scale) + 1e-4


def mutual_nn_unit_int8(d1: np.ndarray, d2: np.ndarray, ratio: float | None, max_distance: float,
                        h1: Int8Rows | None = None, h2: Int8Rows | None = None,
                        buffers: ProductBuffers | None = None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`mutual_nn_unit_bf16` with the candidates from an int8 product (:func:`int8_fast` CPUs).

    Same reasoning as the bfloat16 product: the integer product only selects the pairs that can be
    above the distance test's similarity (``s_min`` less :func:`int8_error_bound`), every decision is
    taken on float32 values. Where the bound leaves no positive threshold (a match distance near
    sqrt(2)) the float32 rule decides directly.
    """
    import torch

    from .words import mutual_nn_unit

    buffers = ProductBuffers() if buffers is None else buffers
    h1 = to_int8(d1) if h1 is None else h1
    h2 = to_int8(d2) if h2 is None else h2
    s_min = 1.0 - 0.5 * max_distance * max_distance
    bound = int8_error_bound(h1, h2)
    denom = h1.scale * h2.scale
    thr = int(np.floor((s_min - bound) * denom))
    if thr <= 0:
        return mutual_nn_unit(d1, d2, ratio, max_distance, return_distances=True)
    with one_thread():
        prod = buffers.product_int8(torch, h1.t, h2.t).numpy()
    rows, cols = _above(buffers, prod, thr)
    upper = thr / denom + bound  # any pair left out is at most this similar (its integer product <= thr)
    return _decide(d1, d2, rows, cols, upper, ratio, max_distance)
