"""Nearest word among a growing set of moving word centres (online vocabulary, docs/vocab_online.md).

Quantising a keyframe against every word costs O(words): at 400k words one keyframe's 1000
descriptors take over a second and a 1.5 GB product. :class:`WordIndex` keeps that exact
product only while the vocabulary is small (below ``ann_min_words``); above it, a graph index
proposes a few candidate words per descriptor and the winner is chosen exactly against the
*current* centres:

- **Projection.** Centres are projected on the top ``ann_pca_dims`` eigenvectors of their
  second-moment matrix (uncentred PCA: it keeps dot products, which is what the search ranks).
  64 of SuperPoint's 256 dimensions make the graph a quarter of the size and its distance
  evaluations four times cheaper; the exact re-ranking below recovers the rest.
- **Graph** (faiss ``IndexHNSWSQ``, inner product, ``ann_hnsw_m`` links per node): a
  hierarchical navigable small-world graph grown one word at a time, searched with a beam of
  ``ann_ef_search``; cost per query ~log(words). The graph keeps each projected word as 8-bit
  codes (``ann_storage: sq8``; ``flat`` keeps float32): a search waits on memory more than it
  computes, and a quarter of the bytes searched ~15% faster for the same candidates, 0.001 less
  agreement with exhaustive search on real SuperPoint words (docs/vocab_online.md). Graph search
  suits SuperPoint descriptors, whose words lie on a low-dimensional set (intrinsic dimension
  ~11 measured on real words): on real words it beat an inverted file (faiss ``IndexIVFFlat``) of the same cost by 4-5
  points of recall (docs/vocab_online.md).
- **Exact re-ranking.** The ``ann_candidates`` best words by projected similarity are scored
  by the full dot product with the current centres; ties go to the lowest word id, as the
  exhaustive ``argmax`` does.
- **Moving centres.** A word's centre is the normalised running mean of its members, so it
  moves as features join. Words founded in the last ``ann_fresh_images`` images (the ones that
  move most: their next members arrive with the next keyframes) are not in the graph yet and
  are searched exhaustively. When an indexed word moves, its new projected position is written
  into the graph's storage (in place), so the graph always ranks current positions; only the
  word's links date from its insertion. That costs nothing in correctness (the re-ranking is
  exact) and little in recall because settled words move little; on real descriptors it beat
  re-inserting drifted words as extra nodes (duplicates crowd the search beam) and leaving
  them where they were inserted (docs/vocab_online.md).
- **Tracked features** (``hints``): a feature matched to one of the previous image's features
  is decided among that feature's best candidates and its word (they were the nearest words a
  descriptor ~0.35 away had), plus the fresh words, without a graph search; every
  ``ann_hint_images`` images a track searches the graph again. A feature that matches nothing in
  the previous image but one of the image before's that the previous image missed (a landmark
  lost for one image, ``ann_hint_gap``) is decided the same way: a match between those two small
  sets replaces ~30% of the graph searches on the synthetic stream (docs/vocab_online.md).
- **Revisited places** (``pool``, :meth:`WordIndex.pool_candidates`): the database hands the
  words of the keyframes around the previous keyframe's best query result; a row still to search
  whose best of those words (scored like the graph scores, by brute force over the pool, then
  exactly) lies within the word radius is decided among them instead of a graph search. On a
  revisit the rows left to search are mostly landmarks entering the view again, whose words the
  old keyframes hold: ~60% fewer graph searches on the synthetic stream (docs/vocab_online.md).
- **Insertion beside the next image** (``ann_background_insert``): the words that settle after an
  image are inserted into the graph on a worker thread (faiss releases the GIL) while the caller
  goes on with what needs no graph: the keyframe's query and insertion into the database, the next
  image's match to this one and its track hints. Every use of the graph waits for that insertion
  first, so the graph, and every answer, is the same as inserting in place; only the wait moves.
  On a new route an image founds ~110 words at ~90 us each (~10 ms), most of it hidden there.
- **Growth.** With ``ann_rebuild_growth`` > 1 the projection and the graph are re-fitted when
  the vocabulary has grown by that factor (a cost linear in the words, so constant per word
  added); by default the graph just grows.

Everything is deterministic: the projection comes from an evenly spaced sample, words enter
the graph one thread at a time in id order (one insertion at a time, finished before any search,
pool scoring or move), and a search does not depend on the thread count.
"""
from __future__ import annotations

from collections import deque
from concurrent.futures import Future
from typing import cast

import numpy as np

from ..errors import ConfigError
from .descriptors import nearest_by_dot
from .faiss_threads import _add_on_one_thread, _insertion_thread, _one_faiss_thread

# the graph is built once at least this many settled words exist (the projection needs data)
_MIN_BUILD_WORDS = 64
# candidates a tracked feature hands to its match in the next image
_HINT_CANDIDATES = 4
# how the graph stores each word's projected position: 8-bit codes (a quarter of the memory, searched
# ~15% faster: the search waits on memory) or float32
_STORAGES = ("sq8", "flat")


def exact_nearest(centres: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(word id, similarity) of each row's nearest centre by dot product (lowest id on ties)."""
    return nearest_by_dot(u, centres, similarities=True)


def _rerank(centres: np.ndarray, u: np.ndarray, cand: np.ndarray, keep: int):
    """Best of each row's candidate ids (-1 = none) by exact similarity, and the ``keep`` best ids."""
    n = len(u)
    cand = np.sort(cand, axis=1)
    cand[:, 1:][cand[:, 1:] == cand[:, :-1]] = -1  # duplicates count once
    valid = cand >= 0
    # np.take gathers the rows ~15 % faster than fancy indexing (the gather is most of the cost)
    rows = np.take(centres, np.where(valid, cand, 0).ravel(), axis=0).reshape(cand.shape + (centres.shape[1],))
    sims = np.matmul(rows, u[:, :, None])[:, :, 0]
    sims[~valid] = -np.inf
    at = sims.argmax(axis=1)  # ids ascend along each row: the lowest id among equal bests
    ids = cand[np.arange(n), at]
    top = sims[np.arange(n), at]
    ids[ids < 0] = 0
    if cand.shape[1] > keep:
        part = np.argpartition(-sims, keep - 1, axis=1)[:, :keep]
        cand = np.take_along_axis(cand, part, axis=1)
        cand[~np.isfinite(np.take_along_axis(sims, part, axis=1))] = -1
    return ids, top.astype(np.float32), cand


def _top_columns(s: np.ndarray, k: int) -> np.ndarray:
    """Column indices of each row's ``k`` largest values (in descending order, lowest index on ties).

    Why not ``np.argpartition``: for the pool's few (4) of ~1,600 columns, ``k`` passes of ``argmax``
    (vectorised, and the winner masked) take 0.23 ms on 200 rows where ``argpartition`` took 1.3 ms.
    ``s`` is overwritten.
    """
    out = np.empty((len(s), k), dtype=np.int64)
    r = np.arange(len(s))
    for i in range(k):
        out[:, i] = at = s.argmax(axis=1)
        s[r, at] = -np.inf
    return out


class WordIndex:
    """Sub-linear nearest-word search over centres that grow and move (see the module doc)."""

    def __init__(self, dim: int, *, min_words: int = 5000, pca_dims: int = 64, hnsw_m: int = 16,
                 ef_search: int = 16, candidates: int = 12, fresh_images: int = 2, hint_images: int = 16,
                 hint_max_distance: float = 0.5, rebuild_growth: float = 0.0, storage: str = "sq8",
                 hint_gap: bool = True, ef_construction: int = 40, background_insert: bool = True):
        if (pca_dims < 1 or hnsw_m < 2 or ef_search < 1 or ef_construction < 1 or candidates < 1
                or fresh_images < 0 or hint_images < 0 or not (rebuild_growth == 0 or rebuild_growth > 1)):
            raise ConfigError("vocab.ann_*: pca_dims, ef_search, ef_construction and candidates must be >= 1, "
                              "hnsw_m >= 2, fresh_images and hint_images >= 0, rebuild_growth 0 (never) or > 1")
        if storage not in _STORAGES:
            raise ConfigError(f"vocab.ann_storage: {storage!r} is not one of {', '.join(_STORAGES)}")
        self.dim = dim
        self.min_words = int(min_words)
        self.pca_dims = min(int(pca_dims), dim)
        self.hnsw_m = int(hnsw_m)
        self.ef_search = int(ef_search)
        self.ef_construction = int(ef_construction)
        self.candidates = int(candidates)
        self.fresh_images = int(fresh_images)
        self.hint_images = int(hint_images)
        self.hint_candidates = min(_HINT_CANDIDATES, self.candidates)
        self.hint_max_distance = float(hint_max_distance)
        self.hint_gap = bool(hint_gap)
        self.rebuild_growth = float(rebuild_growth)
        self.storage = storage
        self.background_insert = bool(background_insert)
        self._pending: Future | None = None  # the insertion running on the worker thread
        self._graph = None  # faiss IndexHNSWSQ / IndexHNSWFlat over the projected words [0, n_indexed)
        self.proj: np.ndarray | None = None  # (dim, pca_dims)
        self.n_indexed = 0
        self.built_at = 0  # word count at the last fit
        self.n_builds = 0
        self.n_searched = 0  # descriptors that searched the graph
        self.n_hinted = 0  # descriptors decided among hints: their match's candidates or a pool's words
        self.n_pooled = 0  # ... of which by a pool's words (IncrementalWords._pool_hints)
        self.insert_cpu_s = 0.0  # CPU seconds of the graph insertions (on whichever thread ran them)
        self._image_ends: deque[int] = deque(maxlen=self.fresh_images + 1)  # word count after each image

    @classmethod
    def from_config(cls, dim: int, conf) -> WordIndex:
        return cls(dim, min_words=conf.ann_min_words, pca_dims=conf.ann_pca_dims, hnsw_m=conf.ann_hnsw_m,
                   ef_search=conf.ann_ef_search, candidates=conf.ann_candidates, fresh_images=conf.ann_fresh_images,
                   hint_images=conf.ann_hint_images, hint_max_distance=conf.ann_hint_max_distance,
                   rebuild_growth=conf.ann_rebuild_growth, storage=conf.ann_storage, hint_gap=conf.ann_hint_gap,
                   ef_construction=conf.ann_ef_construction, background_insert=conf.ann_background_insert)

    @property
    def active(self) -> bool:
        """True once the graph is in use (the vocabulary reached ``min_words``)."""
        return self._graph is not None

    @property
    def graph(self):
        """The faiss graph index, once it holds every word handed to it (see :meth:`wait`)."""
        self.wait()
        return self._graph

    @graph.setter
    def graph(self, value) -> None:
        self.wait()
        self._graph = value

    # ------------------------------------------------------------------ search
    def nearest(self, centres: np.ndarray, u: np.ndarray, hints: np.ndarray | None = None,
                search: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Nearest word of each row of ``u`` (unit float32): (word id, exact similarity, candidates).

        ``hints``: (n, h) extra candidate word ids per row (-1: none); ``search``: rows that
        search the graph (default: all); the other rows are decided among their hints and the
        fresh words. ``candidates`` are each row's best words by exact similarity (-1 padded):
        a feature tracked into the next image takes them as hints. Before the graph exists the
        search is exhaustive.
        """
        n = len(u)
        if self.graph is None or n == 0:
            ids, sims = exact_nearest(centres, u)
            return ids, sims, ids[:, None].copy()
        u = np.ascontiguousarray(u, dtype=np.float32)
        searched = np.ones(n, dtype=bool) if search is None else np.asarray(search, dtype=bool)
        fresh = None
        if len(centres) > self.n_indexed:  # fresh words: exhaustive; their best joins the candidates
            f_ids, _ = exact_nearest(centres[self.n_indexed:], u)
            fresh = (f_ids + self.n_indexed)[:, None]
        ids = np.zeros(n, dtype=np.int64)
        sims = np.full(n, -np.inf, dtype=np.float32)
        keep = np.full((n, self.hint_candidates), -1, dtype=np.int64)
        for rows, found in self._groups(u, searched, hints):
            parts = [found] + ([fresh[rows]] if fresh is not None else [])
            ids[rows], sims[rows], keep[rows] = _rerank(centres, u[rows], np.concatenate(parts, axis=1),
                                                        self.hint_candidates)
        self.n_searched += int(searched.sum())
        self.n_hinted += int(n - searched.sum())
        return ids, sims, keep

    def pool_candidates(self, u: np.ndarray, pool: np.ndarray) -> np.ndarray:
        """Each row's ``hint_candidates`` best words of ``pool`` (word ids) by projected similarity, -1 padded.

        The scoring is the graph's own (the projected words as the graph stores them), brute force
        over the pool instead of a walk through the graph: a few thousand words cost less than a few
        hundred graph searches. Words not in the graph yet are left out (the fresh words are
        searched exhaustively anyway).
        """
        k = self.hint_candidates
        out = np.full((len(u), k), -1, dtype=np.int64)
        pool = pool[pool < self.n_indexed]
        if self.graph is None or len(u) == 0 or len(pool) == 0:
            return out
        assert self.proj is not None  # made with the graph (_build)
        rows = self._storage()[pool]
        if self.storage == "sq8":
            import faiss

            with _one_faiss_thread():
                rows = faiss.downcast_index(self.graph.storage).sa_decode(np.ascontiguousarray(rows))
        s = np.ascontiguousarray(u, dtype=np.float32) @ self.proj @ rows.T
        kk = min(k, len(pool))
        out[:, :kk] = pool[_top_columns(s, kk)]
        return out

    def decide(self, centres: np.ndarray, u: np.ndarray, cand: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Best of each row's candidate word ids (-1: none) by exact similarity: (word id, similarity)."""
        ids, top, _ = _rerank(centres, u, cand, cand.shape[1])
        return ids, top

    def _groups(self, u: np.ndarray, searched: np.ndarray, hints: np.ndarray | None):
        """(rows, candidate ids) for the rows that search the graph and for those decided by hints."""
        rows = np.flatnonzero(searched)
        if len(rows):
            k = self.candidates
            self.graph.hnsw.efSearch = max(self.ef_search, k)
            with _one_faiss_thread():
                found = self.graph.search(np.ascontiguousarray(u[rows] @ self.proj), k)[1]  # node i = word i
            if hints is not None and (hints[rows] >= 0).any():
                found = np.concatenate([found, hints[rows]], axis=1)
            yield rows, found
        rest = np.flatnonzero(~searched)
        if len(rest):
            yield rest, (hints[rest] if hints is not None else np.full((len(rest), 1), -1, dtype=np.int64))

    # ------------------------------------------------------------------ upkeep
    def update(self, centres: np.ndarray, touched: np.ndarray, moved: np.ndarray | None = None) -> None:
        """Called after each image: ``centres`` holds every word, ``touched`` the ids it moved or founded;
        ``moved``, when given, is ``centres[touched]`` already at hand (saves gathering
        ~1000 scattered rows again)."""
        n = len(centres)
        self._image_ends.append(n)
        due = self.graph is None or (self.rebuild_growth > 1 and n >= self.rebuild_growth * self.built_at)
        if due and n >= self.min_words and self._settled(n) >= _MIN_BUILD_WORDS:
            self._build(centres)
            return
        if self.graph is None:
            return
        indexed = touched < self.n_indexed
        if indexed.any():  # moved words: their current projected position, written in place
            old = touched[indexed]
            self._write(old, (centres[old] if moved is None else moved[indexed]) @ self.proj)
        self._index_up_to(centres, self._settled(n), background=self.background_insert)

    def _settled(self, n: int) -> int:
        """Word count ``fresh_images`` images ago: words below it are no longer fresh."""
        if self.fresh_images == 0:
            return n
        return self._image_ends[0] if len(self._image_ends) > self.fresh_images else 0

    def _storage(self) -> np.ndarray:
        """The graph's own per-word rows (a writable view, valid until the next insertion): float32
        (words, pca_dims) vectors with ``flat`` storage, uint8 codes with ``sq8``."""
        import faiss

        store = faiss.downcast_index(self.graph.storage)  # (its stub returns the base Index)
        if self.storage == "flat":
            xb = cast("faiss.IndexFlat", store).get_xb()
            return faiss.rev_swig_ptr(xb, self.graph.ntotal * self.pca_dims).reshape(-1, self.pca_dims)
        sq = cast("faiss.IndexScalarQuantizer", store)
        return faiss.rev_swig_ptr(sq.codes.data(), self.graph.ntotal * sq.code_size).reshape(-1, sq.code_size)

    def _write(self, ids: np.ndarray, projected: np.ndarray) -> None:
        """Words ``ids`` now lie at ``projected`` (their links stay): written into the graph's storage."""
        rows: np.ndarray = np.ascontiguousarray(projected, dtype=np.float32)  # sq8: encoded to uint8
        if self.storage == "sq8":
            import faiss

            with _one_faiss_thread():  # a few hundred rows: OpenMP workers would only wait on a busy core
                rows = faiss.downcast_index(self.graph.storage).sa_encode(rows)
        self._storage()[ids] = rows

    def wait(self) -> None:
        """Return once the graph holds every word handed to it (the worker's insertion finished);
        an error of that insertion is raised here."""
        pending, self._pending = self._pending, None
        if pending is not None:
            self.insert_cpu_s += pending.result()

    def _index_up_to(self, centres: np.ndarray, end: int, background: bool = False) -> None:
        if end <= self.n_indexed:
            return
        p = np.ascontiguousarray(centres[self.n_indexed:end] @ self.proj)
        self.wait()
        if background:
            self._pending = _insertion_thread().submit(_add_on_one_thread, self._graph, p)
        else:
            self.insert_cpu_s += _add_on_one_thread(self.graph, p)
        self.n_indexed = end

    def _build(self, centres: np.ndarray) -> None:
        try:
            import faiss
        except ImportError as e:  # pragma: no cover - faiss-cpu is a dependency
            raise ConfigError(f"the online vocabulary has {len(centres)} words (vocab.ann_min_words = "
                              f"{self.min_words}) and its nearest-word index needs faiss: pip install faiss-cpu") from e
        end = self._settled(len(centres))
        sample = centres[np.linspace(0, end - 1, min(end, 50000)).round().astype(np.int64)]
        _, vecs = np.linalg.eigh((sample.T @ sample).astype(np.float64) / len(sample))
        proj = vecs[:, ::-1][:, : self.pca_dims]
        proj *= np.where(proj[np.abs(proj).argmax(axis=0), np.arange(proj.shape[1])] < 0, -1.0, 1.0)
        self.proj = np.ascontiguousarray(proj, dtype=np.float32)
        if self.storage == "sq8":
            # 8 bits per projected dimension, range per dimension from the settled words (a word
            # outside it is clipped: only its rank among the candidates suffers, the re-ranking is exact)
            # (faiss's stub has a ScalarQuantizer where the constructor takes its QuantizerType, an int)
            self.graph = faiss.IndexHNSWSQ(self.pca_dims, faiss.ScalarQuantizer.QT_8bit,  # type: ignore[arg-type]
                                           self.hnsw_m, faiss.METRIC_INNER_PRODUCT)
            self.graph.train(np.ascontiguousarray(sample @ self.proj))
        else:
            self.graph = faiss.IndexHNSWFlat(self.pca_dims, self.hnsw_m, faiss.METRIC_INNER_PRODUCT)
        self.graph.hnsw.efConstruction = self.ef_construction
        self.n_indexed = 0
        self._index_up_to(centres, end)
        self.built_at = len(centres)
        self.n_builds += 1

    def stats(self) -> dict:
        return {"active": self.active, "indexed": self.n_indexed, "builds": self.n_builds,
                "searched": self.n_searched, "hinted": self.n_hinted, "pooled": self.n_pooled,
                "insert_cpu_s": self.insert_cpu_s}
