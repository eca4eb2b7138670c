"""One line naming the machine a figure was measured on: CPU model, cores, torch's CPU capability, GPU.

Why every benchmark prints it: SuperPoint's speed on a CPU depends above all on the vector
instructions torch and oneDNN may use (AVX2, AVX-512, AMX / AVX512-BF16: several times apart
per forward) and on the cores, so figures from two machines are only comparable when both
lines are known. Capabilities limited by the environment (``ATEN_CPU_CAPABILITY``,
``ONEDNN_MAX_CPU_ISA``: how an AVX2 figure is measured on a newer CPU) are named in the line.
"""
from __future__ import annotations

import os
import platform
from pathlib import Path

# CPU flags that change what SuperPoint's convolutions cost, widest last
_ISA_FLAGS = ("avx2", "avx512f", "avx512_vnni", "avx512_bf16", "amx_bf16", "amx_int8")
# environment variables that limit what torch / oneDNN use
LIMIT_VARIABLES = ("ATEN_CPU_CAPABILITY", "ONEDNN_MAX_CPU_ISA", "DNNL_MAX_CPU_ISA")


def cpu_model() -> str:
    """The CPU's model name (``/proc/cpuinfo``; elsewhere what ``platform`` says)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown CPU"


def cpu_flags() -> list[str]:
    """The vector-instruction flags of :data:`_ISA_FLAGS` the CPU reports (Linux only; else empty)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("flags"):
                have = set(line.split(":", 1)[1].split())
                return [f for f in _ISA_FLAGS if f in have]
    except OSError:
        pass
    return []


def usable_cores() -> int:
    """Cores this process may run on (its affinity mask; ``taskset`` narrows it), else the CPU count."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def limits() -> list[str]:
    """``NAME=value`` of every capability-limiting variable set in the environment."""
    return [f"{k}={os.environ[k]}" for k in LIMIT_VARIABLES if os.environ.get(k)]


def machine_line(device: str | None = None) -> str:
    """The machine line.

    ``machine: <CPU> (<flags>), <n> cores[ of <m>], torch <v> CPU capability <cap>[ limited by ...],
    <t> threads[, GPU <name>]`` (one line).

    ``device``: the device a benchmark ran on; a CUDA device adds the GPU's name. torch is
    imported here (a few seconds on a small machine); without torch the line says so.
    """
    flags = cpu_flags()
    cores, total = usable_cores(), os.cpu_count() or 0
    parts = [f"{cpu_model()}" + (f" ({' '.join(flags)})" if flags else ""),
             f"{cores} cores" + (f" of {total}" if total and total != cores else "")]
    try:
        import torch
    except ImportError:
        parts.append("torch not installed")
    else:
        cap = torch.backends.cpu.get_cpu_capability()
        lim = limits()
        limited = f" (limited: {' '.join(lim)})" if lim else ""
        parts.append(f"torch {torch.__version__} CPU capability {cap}" + limited)
        parts.append(f"{torch.get_num_threads()} torch threads")
        if device is not None and str(device).startswith("cuda") and torch.cuda.is_available():
            parts.append(f"GPU {torch.cuda.get_device_name(torch.device(device))}")
    return "machine: " + ", ".join(parts)
