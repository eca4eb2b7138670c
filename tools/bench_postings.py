#!/usr/bin/env python
"""Inverted index of the BoW database: query + insert per keyframe, per-word lists (the baseline) vs the arena.

The bags of words come once from ``bench_scaling``'s place stream through a vocabulary trained
beforehand on another place stream (as ``bench_scaling.py database --trained K``), or with
``--trained 0`` from an online-mode database grown on that stream (the query's bag, the inserted
bag and the word count of every keyframe), and are cached in ``--bags`` (an .npz, with the
vocabulary beside it). Then two databases get the same bags in
the loop detector's order (query top-5 with the 20 newest excluded, then insert), keyframe by
keyframe and interleaved (the order of the two swaps every keyframe), so both see the same
machine load: one is the current database, the other the former index as the baseline
(``former_database`` below: per-word numpy arrays in Python lists, appended and gathered word
by word, and the former scoring, which weighed every posting at query time). Every query's
candidates must be identical (ids and scores, bit for bit), and at every checkpoint the scores
of a probe against all keyframes too; the run stops otherwise.

Printed at checkpoints: mean CPU ms per keyframe (query, insert, both; CPU time, as other
processes share the machine) of each over the ``--window`` keyframes before it, the ratio
former / current, and the index's memory per keyframe (former: its arrays' data, without the two
numpy objects per word; current: the whole arena and the per-word arrays); then CPU and
wall time of each over the whole run.

    python tools/bench_postings.py [--keyframes 10000] [--trained 200] [--idf vocabulary|database|both]
    python tools/bench_postings.py --trained 0 --bags bench-postings/online.npz   # online-mode bags
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_scaling import LandmarkTable, PlaceStream


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
        for w, n, c in zip(words.tolist(), counts.tolist(), bow.counts.tolist(), strict=True):
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
        k = np.concatenate([kf[w][:n] for w, n in zip(ws, ns, strict=True)]).astype(np.int64)
        t = np.concatenate([tf[w][:n] for w, n in zip(ws, ns, strict=True)])
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

        def scores(self, bow):  # the query's weights as now (unchanged), the former posting arithmetic
            n = len(self)
            out = np.zeros(n)
            weighed = self._query_weights(bow) if n and len(bow) else None
            if weighed is None:
                return out
            words, idf_q, a = weighed
            kf, tf, pos = self._post.gather(words)
            self._last_gather = (len(self), words, kf, tf, pos)
            if not len(kf):
                return out
            nk = self._norms_at(kf)
            b = np.divide(tf * idf_q[pos], nk, out=np.zeros_like(tf), where=nk > 0)
            return np.bincount(kf, weights=np.minimum(a[pos], b), minlength=n)

    return FormerDatabase(vocab, conf)


def _pack(bags: list) -> dict:
    return {"words": np.concatenate([b.words for b in bags]).astype(np.int32),
            "counts": np.concatenate([b.counts for b in bags]).astype(np.uint16),
            "ends": np.cumsum([len(b) for b in bags]).astype(np.int64)}


def _unpack(z, prefix: str, n: int) -> list:
    from slam_lcd.vocab import BowVector

    words = z[prefix + "words"].astype(np.int64)
    counts, ends = z[prefix + "counts"].astype(np.float64), z[prefix + "ends"]
    starts = np.concatenate([[0], ends[:-1]])
    return [BowVector(words[a:b], counts[a:b]) for a, b in zip(starts[:n], ends[:n], strict=True)]


def make_bags(n: int, trained: int, seed: int, path: Path) -> None:
    """Bags of ``n`` keyframes of the place stream, saved (atomically) with what the replay needs.

    Trained (``trained`` > 0): the vocabulary (saved beside the bags), and each keyframe's bag of its
    words, which is both the query's and the inserted one. Online (``trained`` = 0): an online
    database grown as the loop detector does; per keyframe the query's bag (nearest existing words),
    the inserted one (with the words it founds) and the word count after the insert.
    """
    from slam_lcd.files.atomic import atomic_write
    from slam_lcd.vocab import BowDatabase, BowVector, VocabConfig, train_vocabulary

    stream = PlaceStream(n, seed, landmarks=LandmarkTable(seed))
    arrays = {"trained": np.array(trained), "seed": np.array(seed)}
    t = time.perf_counter()
    if trained:
        other = PlaceStream(trained, seed + 101, landmarks=LandmarkTable(seed + 101))
        vocab = train_vocabulary([other.keyframe(k) for k in range(trained)], VocabConfig())
        print(f"vocabulary: {len(vocab)} words from {trained} keyframes of another place stream "
              f"in {time.perf_counter() - t:.0f} s", flush=True)
        bags = []
        for k in range(n):
            bags.append(BowVector.from_word_ids(vocab.quantize(stream.keyframe(k))))
            if (k + 1) % 1000 == 0:
                print(f"  quantised {k + 1} keyframes ({time.perf_counter() - t:.0f} s)", flush=True)
        vocab.save(vocab_path(path))
    else:
        db = BowDatabase(None, VocabConfig(idf_source="database"))
        queries, bags, n_words = [], [], []
        for k in range(n):
            d = stream.keyframe(k)
            queries.append(db.transform(d))
            bags.append(db.add(k, k * 10**8, d))
            n_words.append(db.n_words)
            if (k + 1) % 1000 == 0:
                print(f"  online database grown to {k + 1} keyframes ({time.perf_counter() - t:.0f} s)", flush=True)
        arrays.update({"q_" + key: v for key, v in _pack(queries).items()}, n_words=np.array(n_words, np.int64))
    arrays.update(_pack(bags))
    with atomic_write(path, "wb") as fh:
        np.savez(fh, **arrays)


def vocab_path(bags: Path) -> Path:
    return bags.with_name(bags.stem + "_vocab.npz")


def replay(vocab, frames: list, idf_source: str, checkpoints: list[int], window: int) -> None:
    """Both databases on the same bags, interleaved; prints a row per checkpoint.

    ``frames``: per keyframe (query bag, inserted bag, word count before, word count after); the
    word counts are None with a vocabulary, else the online run's, given to the databases through a
    stand-in for their growing words (the replay does not grow words: only the index is timed).
    """
    from types import SimpleNamespace

    from slam_lcd.vocab import BowDatabase, VocabConfig

    conf = VocabConfig(idf_source=idf_source)
    dbs = {"former": former_database(vocab, conf), "current": BowDatabase(vocab, conf)}
    if vocab is None:
        for db in dbs.values():
            db.words = SimpleNamespace(n_words=0)
    n = len(frames)
    times = {name: np.zeros((n, 2)) for name in dbs}
    order = list(dbs)
    print(f"-- idf from the {idf_source}: {'kf':>6s} {'query':>15s} {'insert':>15s} {'query+insert':>22s} "
          f"{'index kB/kf':>15s}")
    print(f"   {'':25s} {'former current':>15s} {'former current':>15s} {'former current ratio':>22s} "
          f"{'former current':>15s}")
    wall = {name: 0.0 for name in dbs}
    for k, (query, bow, n_before, n_after) in enumerate(frames):
        got = {}
        for name in order:
            db = dbs[name]
            if n_before is not None:
                db.words.n_words = n_before
            w0, t0 = time.perf_counter(), time.process_time()
            cands = db.query(query, top_k=5, exclude_recent_n=20) if len(db) else []
            t1 = time.process_time()
            if n_after is not None:
                db.words.n_words = n_after
            db.add_bow(k, k * 10**8, bow)
            t2 = time.process_time()
            wall[name] += time.perf_counter() - w0
            times[name][k] = (t1 - t0, t2 - t1)
            got[name] = [(c.match_id, c.bow_score) for c in cands]
        order.reverse()
        if got["former"] != got["current"]:
            raise SystemExit(f"keyframe {k}: candidates differ: former {got['former']} current {got['current']}")
        if k + 1 in checkpoints:
            probe = frames[k // 2][1]
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
    cpu = {name: t.sum() for name, t in times.items()}
    print(f"   over all {n} keyframes: CPU time former {cpu['former']:.1f} s, current {cpu['current']:.1f} s, "
          f"x{cpu['former'] / cpu['current']:.2f}; wall time former {wall['former']:.1f} s, current "
          f"{wall['current']:.1f} s, x{wall['former'] / wall['current']:.2f}; scores and candidates identical at "
          f"every step")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--keyframes", type=int, default=10000)
    ap.add_argument("--trained", type=int, default=200, metavar="K",
                    help="the vocabulary is trained on K keyframes of another place stream (default 200; "
                         "0: bags of an online-mode run, database idf)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--bags", default="bench-postings/bags.npz",
                    help="cache of the bags of words (made when missing or made for other settings)")
    ap.add_argument("--idf", choices=["vocabulary", "database", "both"], default="both",
                    help="with a trained vocabulary: whose idf (online mode: always the database's)")
    ap.add_argument("--window", type=int, default=200, help="keyframes before each checkpoint that are averaged")
    args = ap.parse_args(argv)
    from slam_lcd.runtime.machine import machine_line

    print(machine_line(), flush=True)  # figures are only comparable with the machine named
    from slam_lcd.vocab import Vocabulary

    path = Path(args.bags)
    fresh = not path.exists() or (args.trained and not vocab_path(path).exists())
    if not fresh:
        with np.load(path, allow_pickle=False) as z:
            fresh = int(z["trained"]) != args.trained or int(z["seed"]) != args.seed or len(z["ends"]) < args.keyframes
    if fresh:
        make_bags(args.keyframes, args.trained, args.seed, path)
    n = args.keyframes
    with np.load(path, allow_pickle=False) as z:
        bags = _unpack(z, "", n)
        if args.trained:
            vocab = Vocabulary.load(vocab_path(path))
            frames = [(b, b, None, None) for b in bags]
            what, idfs = f"{len(vocab)} trained words", ["vocabulary", "database"] if args.idf == "both" else [args.idf]
        else:
            vocab, after = None, z["n_words"][:n].tolist()
            frames = list(zip(_unpack(z, "q_", n), bags, [0] + after[:-1], after, strict=True))
            what, idfs = f"online words (to {after[-1]})", ["database"]
    n = len(frames)
    print(f"== BoW index: {n} keyframes, {what}, {sum(len(f[1]) for f in frames) / n:.0f} words per keyframe; "
          f"mean CPU ms per keyframe over the {args.window} keyframes before each checkpoint ==")
    checkpoints = sorted({c for c in (1000, 3000, 5000, 10000) if c <= n} | {n})
    for idf in idfs:
        replay(vocab, frames, idf, checkpoints, args.window)


if __name__ == "__main__":
    main()
