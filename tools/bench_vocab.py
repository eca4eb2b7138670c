#!/usr/bin/env python
"""Speed of vocabulary quantisation and database queries, each next to a brute-force baseline.

Targets: quantising 1000 descriptors into ~100k words < 10 ms on CPU; a query
against a database of 10,000 keyframes < 10 ms. The 100k-word vocabularies are synthetic
(the descent cost depends on the tree's shape, not on how it was trained): a DBoW2-shaped
tree (k=10, L=5) and a DP-shaped one (branching drawn from 4..32 per node, as the DP tree's
inferred branching varies). The keyframe database holds 10,000 bags of words with a
Zipf-like word distribution (~500 features per keyframe).

    python tools/bench_vocab.py [--words 100000] [--keyframes 10000] [--repeat 20] [--threads N]
"""
from __future__ import annotations

import argparse
import functools
import os
import statistics
import time

import numpy as np


def synthetic_tree(rng, lo, hi, n_words, dim):
    """Tree whose children are noisy copies of their parent, branching drawn from lo..hi per node,
    levels added until about ``n_words`` leaves (the last level's branching is scaled to hit it)."""
    from slam_lcd.vocab.descriptors import normalise_rows
    from slam_lcd.vocab.tree import VocabTree

    centres, parents = [], []
    cur = normalise_rows(rng.normal(size=(1, dim)))
    lvl = 0
    while len(cur) < n_words:
        b = rng.integers(lo, hi + 1, size=len(cur))
        if len(cur) * (lo + hi) / 2 > n_words:  # last level: scale the branching to reach ~n_words
            m = n_words / len(cur)
            b = rng.integers(max(1, int(m * lo / hi * 2 / 2)), min(hi, int(np.ceil(m * 2 * hi / (lo + hi)))) + 1,
                             size=len(cur))
            b = np.maximum(1, np.round(b * n_words / b.sum())).astype(int)
        par = np.repeat(np.arange(len(cur)), np.minimum(b, hi))
        noise = (1.2 * 0.6 ** lvl) / np.sqrt(dim)
        cur = normalise_rows(cur[par] + noise * rng.normal(size=(len(par), dim)))
        centres.append(cur.astype(np.float32))
        parents.append(par)
        lvl += 1
    return VocabTree(centres, parents)


def timed(fn, repeat):
    fn()
    ts = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts) * 1e3


def bench_quantize(args, rng):
    from slam_lcd.vocab.descriptors import normalise_rows

    print(f"== quantising 1000 descriptors (D={args.dim}) ==")
    from slam_lcd.vocab import VocabConfig

    cap = VocabConfig().max_branching
    shapes = {"DBoW2-shaped k=10 L=5": (10, 10), f"DP-shaped (4..{cap} children)": (4, cap)}
    for name, (lo, hi) in shapes.items():
        tree = synthetic_tree(rng, lo, hi, args.words, args.dim)
        words = tree.words
        picked = words[rng.integers(0, len(words), 1000)]  # drawn before the noise
        x = normalise_rows(picked + 0.15 * rng.normal(size=(1000, args.dim)) / np.sqrt(args.dim))
        t_greedy = timed(functools.partial(tree.quantize, x), args.repeat)
        t_brute = timed(functools.partial(tree.quantize_exhaustive, x, chunk=1000), max(2, args.repeat // 10))
        agree = float((tree.quantize(x) == tree.quantize_exhaustive(x)).mean())
        widths = [int(b.max()) for b in tree.branching()]
        print(f"{name:28s} words={tree.n_words:7d} depth={tree.depth} max-branching/level={widths}")
        print(f"   greedy tree descent: {t_greedy:7.2f} ms   brute-force nearest word: {t_brute:8.1f} ms   "
              f"speed-up x{t_brute / t_greedy:6.1f}   greedy==exhaustive {agree:.3f}   target < 10 ms: "
              f"{'OK' if t_greedy < 10 else 'MISSED'}")


def bench_query(args, rng):
    from slam_lcd.vocab import BowDatabase, BowVector, VocabConfig, bow_similarity
    from slam_lcd.vocab.tree import VocabTree
    from slam_lcd.vocab.vocabulary import Vocabulary

    print(f"== querying a database of {args.keyframes} keyframes ({args.words} words, ~500 features each) ==")
    # a vocabulary object is only needed for its size and idf: a flat one-level tree of random unit words
    dim = 8
    words = rng.normal(size=(args.words, dim)).astype(np.float32)
    words /= np.linalg.norm(words, axis=1, keepdims=True)
    tree = VocabTree([words], [np.zeros(args.words, dtype=np.int64)])
    p = 1.0 / np.arange(1, args.words + 1) ** 0.9
    p /= p.sum()
    perm = rng.permutation(args.words)
    df = np.zeros(args.words)

    def random_bow():
        ids = perm[rng.choice(args.words, size=500, p=p)]
        return BowVector.from_word_ids(ids)

    bows = [random_bow() for _ in range(args.keyframes)]
    for b in bows:
        df[b.words] += 1
    idf = np.log(args.keyframes / np.maximum(df, 1))
    vocab = Vocabulary(tree, idf, np.ones(args.words), df, args.keyframes, "float", dim)
    for source in ("vocabulary", "database"):
        db = BowDatabase(vocab, VocabConfig(idf_source=source))
        t0 = time.perf_counter()
        for i, b in enumerate(bows):
            db.add_bow(i, i * 10**8, b)
        t_build = time.perf_counter() - t0
        queries = [random_bow() for _ in range(args.repeat)]
        it = iter(queries * 3)
        t_q = timed(lambda db=db, it=it: db.query(next(it), top_k=5, exclude_recent_n=50), args.repeat - 1)
        q = queries[0]
        cur_idf = db.idf()
        n_brute = min(1000, args.keyframes)
        t0 = time.perf_counter()
        brute = [bow_similarity(q, bows[i], cur_idf) for i in range(n_brute)]
        t_brute = (time.perf_counter() - t0) * 1e3 * args.keyframes / n_brute
        ok = np.allclose(db.scores(q)[:n_brute], brute)
        print(f"idf from {source:10s}: build {t_build:5.1f} s   inverted-index query {t_q:6.2f} ms   "
              f"brute-force scoring of every keyframe {t_brute:8.1f} ms (extrapolated from {n_brute})   "
              f"x{t_brute / t_q:6.1f}   scores equal: {ok}   target < 10 ms: {'OK' if t_q < 10 else 'MISSED'}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--words", type=int, default=100_000, help="vocabulary size of the database benchmark")
    ap.add_argument("--keyframes", type=int, default=10_000)
    ap.add_argument("--dim", type=int, default=256)
    ap.add_argument("--repeat", type=int, default=20)
    ap.add_argument("--threads", type=int, default=None, help="BLAS threads (default: library default)")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    if args.threads:
        from threadpoolctl import threadpool_limits

        threadpool_limits(args.threads)
    from slam_lcd.runtime.machine import machine_line

    print(machine_line(), flush=True)  # figures are only comparable with the machine named
    print(f"load average: {os.getloadavg()[0]:.1f}")
    rng = np.random.default_rng(args.seed)
    bench_quantize(args, rng)
    bench_query(args, rng)


if __name__ == "__main__":
    main()
