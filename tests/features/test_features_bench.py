"""tools/bench_features.py runs end to end (tiny sizes; the real figures come from running it)."""
from __future__ import annotations

import json

import torch

from support.module_files import load_module
from support.paths import REPO

TOOL = REPO / "tools" / "bench_features.py"


def load_tool():
    return load_module(TOOL, "bench_features")


def test_bench_tool_reports_every_figure(tmp_path, capsys):
    out = tmp_path / "bench.json"
    threads = torch.get_num_threads()
    try:
        rc = load_tool().main(["--sizes", "61x45", "--batches", "1,2", "--reps", "1", "--device", "cpu",
                               "--threads", "1", "--json", str(out)])
    finally:
        torch.set_num_threads(threads)
    assert rc == 0
    rows = json.loads(out.read_text())
    sp = [r for r in rows if r["extractor"] == "superpoint"]
    orb = [r for r in rows if r["extractor"] == "orb"]
    assert len(sp) == 2 and len(orb) == 2
    for r in sp:
        assert r["forward_ms"] > 0 and r["full_ms"] > 0 and r["ratio"] > 0
    assert "full ms" in capsys.readouterr().out
