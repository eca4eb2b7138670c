"""SuperPoint as an :class:`~slam_lcd.features.extract.Extractor`: numpy images in, Features out.

Why a module of its own: it is the only extractor that needs torch, and importing torch costs
~3 s on a 2-core machine; :func:`slam_lcd.features.loading.load_extractor` imports this module
only for ``features.kind: superpoint``.
"""
from __future__ import annotations

import hashlib
import logging
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np
import torch

from ..errors import ConfigError
from ..files.hashing import sha256_of
from ..types import Features
from ..vision.gray import to_gray_float
from .allocator import retain_freed_memory, trim_when_fragmented
from .config import FeaturesConfig
from .extract import Extractor
from .resize import downscale, to_full_resolution
from .superpoint import SuperPoint
from .weights import load_state_dict_checked, resolve_weights

log = logging.getLogger(__name__)


def resolve_device(device: str) -> torch.device:
    if device == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if device == "cuda" and not torch.cuda.is_available():
        raise ConfigError("features.device is 'cuda' but PyTorch sees no CUDA device; use 'cpu' or 'auto'")
    if device not in ("cpu", "cuda") and not device.startswith("cuda:"):
        raise ConfigError(f"features.device must be 'auto', 'cpu' or 'cuda', got {device!r}")
    return torch.device(device)


def bfloat16_is_native(device: torch.device) -> bool:
    """Whether ``device`` computes bfloat16 convolutions in hardware (oneDNN's check on CPU: AVX512-BF16 / AMX)."""
    if device.type == "cuda":
        return torch.cuda.is_bf16_supported()
    try:
        return bool(torch.ops.mkldnn._is_mkldnn_bf16_supported())
    except (AttributeError, RuntimeError):  # pragma: no cover - a torch without oneDNN
        return False


def resolve_precision(precision: str, device: torch.device) -> str:
    """``auto`` -> ``bfloat16`` where ``device`` computes it natively, else ``float32``; others as they are."""
    if precision == "auto":
        return "bfloat16" if bfloat16_is_native(device) else "float32"
    return precision


class SuperPointExtractor(Extractor):
    """SuperPoint on CPU or CUDA, batched, under ``torch.inference_mode``."""

    kind = "superpoint"
    descriptor_dim = 256
    descriptor_dtype = np.float32

    def __init__(self, conf: FeaturesConfig, weights: str | Path | None = None, device: str = "auto",
                 model: SuperPoint | None = None):
        super().__init__(conf)
        self.device = resolve_device(device)
        if model is None:
            self.weights_path: Path | None = resolve_weights(
                weights or conf.weights,
                cache=conf.cache_dir,
                url=conf.weights_url,
                sha256=conf.weights_sha256,
                allow_download=conf.allow_download,
            )
            model = SuperPoint(self.model_conf(conf, self.device))
            load_state_dict_checked(model, self.weights_path)
            self._weights_id = sha256_of(self.weights_path)
        else:  # an in-memory model (tests, benchmarks): identify it by its parameters
            self.weights_path = None
            h = hashlib.sha256()
            for k, v in model.state_dict().items():
                h.update(k.encode())
                h.update(v.detach().cpu().numpy().tobytes())
            self._weights_id = h.hexdigest()
        self.model = model.eval().to(self.device)
        self._channels_last = self.device.type == "cpu" and conf.cpu_channels_last
        if self._channels_last:
            # torch's stubs leave memory_format out of Module.to
            self.model = self.model.to(memory_format=torch.channels_last)  # type: ignore[call-overload]
        self._trim_heap = self.device.type == "cpu" and conf.cpu_allocator == "retain"
        if self._trim_heap:
            retain_freed_memory()
        self.precision = str(self.model.conf["backbone_precision"])  # what 'auto' became on this device
        if conf.precision == "bfloat16" and not bfloat16_is_native(self.device):
            log.warning("features.precision bfloat16: this %s has no native bfloat16 arithmetic; SuperPoint runs "
                        "emulated and slower than float32", "CPU" if self.device.type == "cpu" else "GPU")

    @staticmethod
    def model_conf(conf: FeaturesConfig, device: torch.device | None = None) -> dict:
        """The model's settings; ``features.precision: auto`` resolved for ``device`` (default: the CPU)."""
        if conf.nms_radius < 0 or conf.remove_borders < 0:
            raise ConfigError("features.nms_radius and features.remove_borders must be >= 0")
        if conf.max_keypoints == 0 or conf.max_keypoints < -1:
            raise ConfigError(f"features.max_keypoints must be positive or -1 (all), got {conf.max_keypoints}")
        return {
            "nms_radius": conf.nms_radius,
            "keypoint_threshold": conf.keypoint_threshold,
            "max_keypoints": conf.max_keypoints,
            "remove_borders": conf.remove_borders,
            "descriptor_sampling": conf.descriptor_sampling,
            "backbone_precision": resolve_precision(conf.precision, device or torch.device("cpu")),
        }

    def identity(self) -> dict:
        ident = {"kind": self.kind, "weights_sha256": self._weights_id, **self.model.conf}
        if ident["backbone_precision"] == "float32":  # the reference arithmetic: caches from before it had a name stay
            del ident["backbone_precision"]
        if self._channels_last:  # a different summation order: results differ in the last digits
            ident["layout"] = "channels_last"
        if self.conf.resize_max is not None:  # unset: the key is unchanged, existing caches stay valid
            ident["resize_max"] = self.conf.resize_max
        return ident

    def _run(self, grays: Sequence[np.ndarray], full_sizes: Sequence[tuple[int, int]] | None = None) -> list[Features]:
        """Features of same-sized gray images; ``full_sizes`` (w, h): the sizes they were downscaled from
        (``features.resize_max``), whose pixels the keypoints are reported in."""
        h, w = grays[0].shape
        full_sizes = full_sizes or [(w, h)] * len(grays)
        batch = torch.from_numpy(np.stack(grays)[:, None])
        if self._channels_last:
            batch = batch.contiguous(memory_format=torch.channels_last)
        with torch.inference_mode():
            out = self.model({"image": batch.to(self.device, non_blocking=True)})
            if self._trim_heap:  # the retained heap's holes do not pile up (features/allocator.py)
                trim_when_fragmented()
            counts = [len(k) for k in out["keypoints"]]
            # one device-to-host copy for the whole batch: [x, y, score, descriptor...] rows
            packed = torch.cat(
                [torch.cat([k, s[:, None], d], dim=1) for k, s, d in
                 zip(out["keypoints"], out["keypoint_scores"], out["descriptors"], strict=True)]
            ).float().cpu().numpy()
        feats = []
        for rows, full in zip(np.split(packed, np.cumsum(counts)[:-1]), full_sizes, strict=True):
            feats.append(
                Features(
                    keypoints=to_full_resolution(np.ascontiguousarray(rows[:, :2]), (w, h), full),
                    scores=np.ascontiguousarray(rows[:, 2]),
                    descriptors=np.ascontiguousarray(rows[:, 3:]),
                    image_size=(int(full[0]), int(full[1])),
                    kind=self.kind,
                )
            )
        return feats

    def _gray(self, image: np.ndarray) -> tuple[np.ndarray, tuple[int, int]]:
        """The network's input (downscaled to ``features.resize_max``) and the image's own size (w, h)."""
        gray = to_gray_float(image)
        return downscale(gray, self.conf.resize_max), (gray.shape[1], gray.shape[0])

    def extract(self, image: np.ndarray) -> Features:
        gray, full = self._gray(image)
        return self._run([gray], [full])[0]

    def extract_batch(self, images: Iterable[np.ndarray]) -> list[Features]:
        """Batched extraction; images of different (network input) sizes are grouped by size."""
        pairs = [self._gray(im) for im in images]
        result: list[Features | None] = [None] * len(pairs)
        by_shape: dict[tuple[int, int], list[int]] = {}
        for i, (g, _) in enumerate(pairs):
            by_shape.setdefault(g.shape, []).append(i)
        bs = max(1, self.conf.batch_size)
        for idx in by_shape.values():
            for s in range(0, len(idx), bs):
                chunk = idx[s : s + bs]
                feats = self._run([pairs[i][0] for i in chunk], [pairs[i][1] for i in chunk])
                for i, f in zip(chunk, feats, strict=True):
                    result[i] = f
        return result  # type: ignore[return-value]
