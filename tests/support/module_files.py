"""Helpers shared by tests: a script of tools/ or examples/ loaded as a module, a SuperPoint of random weights."""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

import torch

from slam_lcd.features import FeaturesConfig, SuperPoint, SuperPointExtractor


def load_module(path: Path, name: str) -> ModuleType:
    """The Python file ``path`` imported as module ``name`` (registered: dataclasses look their module up)."""
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod


def random_extractor(seed=0, **changes) -> SuperPointExtractor:
    """A SuperPoint extractor on the CPU with seeded random weights (``changes``: FeaturesConfig fields)."""
    conf = FeaturesConfig(**changes)
    torch.manual_seed(seed)
    return SuperPointExtractor(conf, device="cpu", model=SuperPoint(SuperPointExtractor.model_conf(conf)))
