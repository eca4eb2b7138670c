#!/usr/bin/env python
"""Inverted index of the BoW database (issue #13): query + insert per keyframe, former store vs current.

The bags of words come once from ``bench_scaling``'s place stream through a vocabulary trained
beforehand on another place stream (as ``bench_scaling.py database --trained K``), and are cached
in ``--bags`` (an .npz, with the vocabulary beside it). Then two databases get the same bags in
the loop detector's order (query top-5 with the 20 newest excluded, then insert), keyframe by
keyframe and interleaved (the order of the two swaps every keyframe), so both see the same
machine load: one is the current database, the other the former index as the baseline
(``former_database`` below: per-word numpy arrays in Python lists, appended and gathered word
by word, and the former scoring, which weighs every posting at query time). Every query's candidates must be identical (ids and scores, bit for bit), and at
every checkpoint the scores of a probe against all keyframes too; the run stops otherwise.

Printed at checkpoints: mean ms per keyframe (query, insert, both) of each store over the
``--window`` keyframes before it, the ratio former / current, and the bytes each store holds
per keyframe.

    python tools/bench_postings.py [--keyframes 10000] [--trained 200] [--idf vocabulary|database|both]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_scaling import LandmarkTable, PlaceStream  # noqa: E402


class PerWordPostings:
    """The former store: one growable (keyframe int32, term count float64) pair per word, in Python lists."""

    def __init__(self):
        self.kf: list[np.ndarray | None] = []
        self.tf: list[np.ndarray | None] = []
        self.size = np.zeros(0, dtype=np.int64)

    @property
    def nbytes(self) -> int:
        """Array data held (not counting the numpy object per array, ~100 bytes each)."""
        return self.size.nbytes + 8 * 2 * len(self.kf) + \
            sum(a.nbytes for a in self.kf if a is not None) + sum(a.nbytes for a in self.tf if a is not None)

    def append(self, kf_index: int, bow) -> None:
        kf, tf, size = self.kf, self.tf, self.size
        top = int(bow.words[-1]) + 1 if len(bow) else 0
        if top > len(size):
            grow = max(top, 2 * len(size)) - len(size)
            kf.extend([None] * grow)
            tf.extend([None] * grow)
            self.size = size = np.concatenate([size, np.zeros(grow, np.int64)])
        words = bow.words
        counts = size[words]
        for w, n, c in zip(words.tolist(), counts.tolist(), bow.counts.tolist()):
            if n == 0:
                kf[w] = np.empty(2, dtype=np.int32)
                tf[w] = np.empty(2, dtype=np.float64)
            elif n == len(kf[w]):
                kf[w] = np.concatenate([kf[w], np.empty(n, dtype=np.int32)])
                tf[w] = np.concatenate([tf[w], np.empty(n, dtype=np.float64)])
            kf[w][n] = kf_index
            tf[w][n] = c
        size[words] = counts + 1

    def gather(self, words: np.ndarray):
        size = self.size
        lens = np.zeros(len(words), dtype=np.int64)
        inside = words < len(size)
        lens[inside] = size[words[inside]]
        at = np.flatnonzero(lens)
        if not len(at):
            e = np.zeros(0, dtype=np.int64)
            return e, np.zeros(0), e
        ws, ns = words[at].tolist(), lens[at].tolist()
        kf, tf = self.kf, self.tf
        k = np.concatenate([kf[w][:n] for w, n in zip(ws, ns)]).astype(np.int64)
        t = np.concatenate([tf[w][:n] for w, n in zip(ws, ns)])
        return k, t, np.repeat(at, lens[at])


def former_database(vocab, conf):
    """A BowDatabase with the former index: ``PerWordPostings`` and the former insert and scoring code."""
    from slam_lcd.vocab import BowDatabase
    from slam_lcd.vocab.database import _Growable

    class FormerDatabase(BowDatabase):
        def __init__(self, vocab, conf):
            super().__init__(vocab, conf)
            self._post = PerWordPostings()
            self._norm_fixed = _Growable(np.float64)

        def _norms_at(self, kf):
            if not self.idf_from_database:
                return self._norm_fixed.a[kf]
            return (np.log(1.0 + len(self)) + 1.0) * self._total.a[kf] - self._logdf_sum.a[kf]

        def _insert(self, kf_id, stamp_ns, bow):
            index = len(self.kf_ids)
            if self.idf_from_database:
                self._df.ensure(self.n_words)
                self._df.n = max(self._df.n, self.n_words)
                kf, tf, pos = self._gather(bow.words)
                old = self._df.a[bow.words]
                delta = np.log(2.0 + old) - np.log(1.0 + old)
                if len(kf):
                    np.add.at(self._logdf_sum.a, kf, tf * delta[pos])
                self._df.a[bow.words] = old + 1.0
                self._logdf_sum.push(float((bow.counts * np.log(2.0 + old)).sum()))
                self._norm_fixed.push(0.0)
            else:
                self._norm_fixed.push(float((bow.counts * self.vocab.idf[bow.words]).sum()))
                self._logdf_sum.push(0.0)
            self._total.push(float(bow.counts.sum()))
            self._stamps.push(int(stamp_ns))
            self._post.append(index, bow)
            self.kf_ids.append(kf_id)
            self._index_of[kf_id] = index
            self._bow_words.append(bow.words.astype(np.int32))
            self._bow_counts.append(np.asarray(bow.counts, dtype=np.float64))

        def _gather(self, words):
            c = self._last_gather
            if c is None or c[0] != len(self) or not len(c[1]) or not len(words):
                return self._post.gather(words)
            c_words, c_kf, c_tf, c_pos = c[1:]
            loc = np.searchsorted(words, c_words)
            hit = (loc < len(words)) & (words[np.minimum(loc, len(words) - 1)] == c_words)
            take = hit[c_pos]
            missing = np.ones(len(words), dtype=bool)
            missing[loc[hit]] = False
            at = np.flatnonzero(missing)
            kf, tf, pos = self._post.gather(words[at])
            return (np.concatenate([c_kf[take], kf]), np.concatenate([c_tf[take], tf]),
                    np.concatenate([loc[c_pos[take]], at[pos]]))

        def scores(self, bow):
            n = len(self)
            out = np.zeros(n)
            if n == 0 or len(bow) == 0:
                return out
            words = bow.words[bow.words < max(self.n_words, 1)] if self.online else bow.words
            counts = bow.counts[: len(words)] if self.online else bow.counts
            idf_q = self.idf(words)
            wq = counts * idf_q
            sq = wq.sum()
            if sq <= 0:
                return out
            a = wq / sq
            kf, tf, pos = self._post.gather(words)
            self._last_gather = (len(self), words, kf, tf, pos)
            if not len(kf):
                return out
            nk = self._norms_at(kf)
            b = np.divide(tf * idf_q[pos], nk, out=np.zeros_like(tf), where=nk > 0)
            return np.bincount(kf, weights=np.minimum(a[pos], b), minlength=n)

    return FormerDatabase(vocab, conf)


def make_bags(n: int, trained: int, seed: int, path: Path) -> None:
    """Train the vocabulary, quantise ``n`` keyframes of the place stream, save both (atomically)."""
    from slam_lcd.atomic import atomic_write
    from slam_lcd.vocab import VocabConfig, train_vocabulary

    conf = VocabConfig()
    other = PlaceStream(trained, seed + 101, landmarks=LandmarkTable(seed + 101))
    t = time.perf_counter()
    vocab = train_vocabulary([other.keyframe(k) for k in range(trained)], conf)
    print(f"vocabulary: {len(vocab)} words from {trained} keyframes of another place stream "
          f"in {time.perf_counter() - t:.0f} s", flush=True)
    stream = PlaceStream(n, seed, landmarks=LandmarkTable(seed))
    words, counts, ends = [], [], []
    t = time.perf_counter()
    for k in range(n):
        w, c = np.unique(vocab.quantize(stream.keyframe(k)), return_counts=True)
        words.append(w.astype(np.int32))
        counts.append(c.astype(np.uint16))
        ends.append((ends[-1] if ends else 0) + len(w))
        if (k + 1) % 1000 == 0:
            print(f"  quantised {k + 1} keyframes ({time.perf_counter() - t:.0f} s)", flush=True)
    vocab.save(vocab_path(path))
    with atomic_write(path, "wb") as fh:
        np.savez(fh, words=np.concatenate(words), counts=np.concatenate(counts), ends=np.array(ends, np.int64),
                 trained=np.array(trained), seed=np.array(seed))


def vocab_path(bags: Path) -> Path:
    return bags.with_name(bags.stem + "_vocab.npz")


def replay(vocab, bags: list, idf_source: str, checkpoints: list[int], window: int) -> None:
    """Both stores on the same bags, interleaved; prints a row per checkpoint."""
    from slam_lcd.vocab import BowDatabase, VocabConfig

    conf = VocabConfig(idf_source=idf_source)
    dbs = {"former": former_database(vocab, conf), "current": BowDatabase(vocab, conf)}
    n = len(bags)
    times = {name: np.zeros((n, 2)) for name in dbs}
    order = list(dbs)
    print(f"-- idf from the {idf_source}: {'kf':>6s} {'query':>15s} {'insert':>15s} {'query+insert':>22s} "
          f"{'store kB/kf':>15s}")
    print(f"   {'':25s} {'former current':>15s} {'former current':>15s} {'former current ratio':>22s} "
          f"{'former current':>15s}")
    cpu0 = {name: 0.0 for name in dbs}
    for k, bow in enumerate(bags):
        got = {}
        for name in order:
            db = dbs[name]
            c0, t0 = time.process_time(), time.perf_counter()
            cands = db.query(bow, top_k=5, exclude_recent_n=20) if len(db) else []
            t1 = time.perf_counter()
            db.add_bow(k, k * 10**8, bow)
            t2 = time.perf_counter()
            cpu0[name] += time.process_time() - c0
            times[name][k] = (t1 - t0, t2 - t1)
            got[name] = [(c.match_id, c.bow_score) for c in cands]
        order.reverse()
        if got["former"] != got["current"]:
            raise SystemExit(f"keyframe {k}: candidates differ: former {got['former']} current {got['current']}")
        if k + 1 in checkpoints:
            probe = bags[k // 2]
            s_old, s_new = dbs["former"].scores(probe), dbs["current"].scores(probe)
            if not np.array_equal(s_old, s_new):
                raise SystemExit(f"keyframe {k}: scores differ (max {np.abs(s_old - s_new).max():.3g})")
            lo = max(0, k + 1 - window)
            m = {name: t[lo:k + 1].mean(axis=0) * 1e3 for name, t in times.items()}
            kb = {name: db._post.nbytes / (k + 1) / 1024 for name, db in dbs.items()}
            both = {name: v.sum() for name, v in m.items()}
            print(f"   {'':17s} {k + 1:6d}    {m['former'][0]:6.2f} {m['current'][0]:7.2f} "
                  f"{m['former'][1]:7.2f} {m['current'][1]:7.2f} {both['former']:9.2f} {both['current']:7.2f} "
                  f"x{both['former'] / both['current']:4.2f} {kb['former']:7.1f} {kb['current']:7.1f}", flush=True)
    print(f"   CPU time over all {n} keyframes: former {cpu0['former']:.1f} s, current {cpu0['current']:.1f} s, "
          f"x{cpu0['former'] / cpu0['current']:.2f}; scores and candidates identical at every step")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--keyframes", type=int, default=10000)
    ap.add_argument("--trained", type=int, default=200, metavar="K",
                    help="the vocabulary is trained on K keyframes of another place stream (default 200)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--bags", default="bench-postings/bags.npz",
                    help="cache of the bags of words (made when missing or made for other settings)")
    ap.add_argument("--idf", choices=["vocabulary", "database", "both"], default="both")
    ap.add_argument("--window", type=int, default=200, help="keyframes before each checkpoint that are averaged")
    args = ap.parse_args(argv)
    from slam_lcd.vocab import BowVector, Vocabulary

    path = Path(args.bags)
    fresh = not path.exists() or not vocab_path(path).exists()
    if not fresh:
        with np.load(path, allow_pickle=False) as z:
            fresh = int(z["trained"]) != args.trained or int(z["seed"]) != args.seed or len(z["ends"]) < args.keyframes
    if fresh:
        make_bags(args.keyframes, args.trained, args.seed, path)
    vocab = Vocabulary.load(vocab_path(path))
    with np.load(path, allow_pickle=False) as z:
        words, counts, ends = z["words"].astype(np.int64), z["counts"].astype(np.float64), z["ends"]
    starts = np.concatenate([[0], ends[:-1]])
    bags = [BowVector(words[a:b], counts[a:b]) for a, b in zip(starts[: args.keyframes], ends[: args.keyframes])]
    n = len(bags)
    print(f"== postings store: {n} keyframes, {len(vocab)} trained words, {ends[n - 1] / n:.0f} words per keyframe; "
          f"mean ms per keyframe over the {args.window} keyframes before each checkpoint ==")
    checkpoints = sorted({c for c in (1000, 3000, 5000, 10000) if c <= n} | {n})
    for idf in (["vocabulary", "database"] if args.idf == "both" else [args.idf]):
        replay(vocab, bags, idf, checkpoints, args.window)


if __name__ == "__main__":
    main()
