"""The machine line every benchmark prints: CPU model, cores, torch's CPU capability (and who limited it)."""
from __future__ import annotations

from slam_lcd.runtime.machine import machine_line

from support.paths import REPO

TOOLS = REPO / "tools"


def test_line_names_cpu_cores_and_torch_capability(monkeypatch):
    monkeypatch.delenv("ATEN_CPU_CAPABILITY", raising=False)
    monkeypatch.delenv("ONEDNN_MAX_CPU_ISA", raising=False)
    line = machine_line()
    assert line.startswith("machine: ") and " cores" in line and "CPU capability" in line
    assert "limited" not in line
    monkeypatch.setenv("ONEDNN_MAX_CPU_ISA", "AVX2")
    assert "limited: ONEDNN_MAX_CPU_ISA=AVX2" in machine_line()


def test_every_benchmark_prints_it():
    tools = sorted(TOOLS.glob("bench_*.py"))
    assert len(tools) > 10
    missing = [t.name for t in tools if "machine_line(" not in t.read_text()]
    assert not missing, f"benchmarks that do not name their machine: {missing}"
