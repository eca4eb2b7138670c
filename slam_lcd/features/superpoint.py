"""SuperPoint: self-supervised interest point detection and description.

DeTone, Malisiewicz, Rabinovich, "SuperPoint: Self-Supervised Interest Point Detection and
Description", CVPR Workshops 2018.

The whole model is in this file: a VGG-style shared encoder, a detector head that
predicts, for every 8x8 cell, a 65-way distribution (64 pixel positions + a "no keypoint"
dustbin), and a descriptor head that predicts a coarse 256-D descriptor map. Parameter
names are those of the official Magic Leap state dict (``conv1a.weight`` ... ``convDb.bias``)
so ``load_state_dict(strict=True)`` accepts ``superpoint_v1.pth`` unchanged.

Tensors in, dict out::

    model = SuperPoint({"max_keypoints": 1000}).eval()
    model.load_state_dict(torch.load(path, weights_only=True))
    out = model({"image": img})   # img: B x 1 x H x W, float in [0, 1]
    out["keypoints"][b]            # N x 2 (x, y) pixels, float32
    out["keypoint_scores"][b]      # N
    out["descriptors"][b]          # N x 256, unit L2 norm

Post-processing is written to cost little next to the convolutions: the score map is
built with a softmax and a pixel shuffle, NMS is one pass of a separable sliding-window
maximum over the full-resolution score map, the strongest keypoints are chosen with
``topk`` and the descriptors are read with one ``grid_sample`` per image.
"""
from __future__ import annotations

import contextlib

import torch
import torch.nn.functional as F
from torch import nn

CELL = 8  # the encoder downsamples by 2**3


@contextlib.contextmanager
def serial_on_cpu(device: torch.device):
    """Run the enclosed CPU tensor ops on one thread.

    Post-processing is a string of cheap element-wise ops. Splitting each over OpenMP
    threads buys little when the cores are free and costs a great deal when they are shared:
    every op ends in a barrier that waits for a descheduled thread. Measured at 640x480 on
    a loaded 2-core machine: 213 ms (2 threads) vs 12 ms (1 thread), median. The
    convolutions keep every thread.
    """
    n = torch.get_num_threads()
    if device.type != "cpu" or n == 1:
        yield
        return
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(n)


def _window_max(x: torch.Tensor, radius: int, dim: int) -> torch.Tensor:
    """Maximum over a sliding window of 2r+1 along ``dim`` (borders padded with -inf).

    Built from ``log2(2r+1)`` element-wise maxima of shifted views (window lengths 1, 2,
    4, 8, ... then one last shift), which on CPU is an order of magnitude faster than
    ``max_pool2d`` with the same window.
    """
    k = 2 * radius + 1
    pad = [0, 0] * (x.dim() - 1 - dim) + [radius, radius]
    m = F.pad(x, pad, value=float("-inf"))
    length = 1
    while 2 * length <= k:
        n = m.shape[dim] - length
        m = torch.maximum(m.narrow(dim, 0, n), m.narrow(dim, length, n))
        length *= 2
    rest = k - length
    if rest:
        n = m.shape[dim] - rest
        m = torch.maximum(m.narrow(dim, 0, n), m.narrow(dim, rest, n))
    return m


def max_pool_nms(scores: torch.Tensor, radius: int) -> torch.Tensor:
    """Boolean mask of the pixels that are the maximum of their (2r+1)^2 window.

    One pass of a separable window maximum (rows, then columns) on the B x H x W score
    map: exactly the square-window max-pool, without its cost.
    """
    if radius <= 0:
        return torch.ones_like(scores, dtype=torch.bool)
    pooled = _window_max(_window_max(scores, radius, dim=2), radius, dim=1)
    return scores == pooled


def sample_descriptors(
    keypoints: torch.Tensor, descriptor_map: torch.Tensor, mode: str = "bilinear"
) -> torch.Tensor:
    """Interpolate a 1/8-resolution descriptor map (1 x D x Hc x Wc) at pixel keypoints (N x 2).

    Cell ``i`` covers pixels ``[8i, 8i+8)``, so its centre is pixel ``8i + 3.5``; the
    keypoint's position in cell units is ``(x - 3.5) / 8``. Returns N x D unit vectors.
    """
    _, d, hc, wc = descriptor_map.shape
    if len(keypoints) == 0:
        return descriptor_map.new_zeros((0, d))
    cells = (keypoints - (CELL / 2 - 0.5)) / CELL
    scale = keypoints.new_tensor([max(wc - 1, 1), max(hc - 1, 1)])
    grid = (cells / scale * 2 - 1).view(1, 1, -1, 2)
    desc = F.grid_sample(descriptor_map, grid, mode=mode, padding_mode="border", align_corners=True)
    desc = desc.view(d, -1).t()
    return F.normalize(desc, p=2, dim=1)


# the first block's activations on the CPU stay under this (glibc's per-thread heaps hold at most 64 MB)
STRIPE_BYTES = 32 << 20


class SuperPoint(nn.Module):
    """The SuperPoint network with keypoint selection and descriptor sampling."""

    default_conf = {
        "descriptor_dim": 256,
        "nms_radius": 4,
        "keypoint_threshold": 0.015,
        "max_keypoints": -1,  # -1: keep every keypoint above the threshold
        "remove_borders": 4,
        "descriptor_sampling": "bilinear",  # or "bicubic"
        "backbone_precision": "float32",  # or "bfloat16": the eight shared convolutions in bfloat16 (autocast)
    }

    def __init__(self, conf: dict | None = None, **kwargs):
        super().__init__()
        unknown = set(conf or {}) | set(kwargs)
        unknown -= set(self.default_conf)
        if unknown:
            raise ValueError(f"unknown SuperPoint option(s) {sorted(unknown)}")
        self.conf = {**self.default_conf, **(conf or {}), **kwargs}
        if self.conf["descriptor_sampling"] not in ("bilinear", "bicubic"):
            raise ValueError("descriptor_sampling must be 'bilinear' or 'bicubic', "
                             f"got {self.conf['descriptor_sampling']!r}")
        if self.conf["backbone_precision"] not in ("float32", "bfloat16"):
            raise ValueError("backbone_precision must be 'float32' or 'bfloat16', "
                             f"got {self.conf['backbone_precision']!r}")

        c1, c2, c3, c4, c5 = 64, 64, 128, 128, 256
        self.relu = nn.ReLU(inplace=True)
        self.pool = nn.MaxPool2d(kernel_size=2, stride=2)
        # Shared encoder.
        self.conv1a = nn.Conv2d(1, c1, kernel_size=3, stride=1, padding=1)
        self.conv1b = nn.Conv2d(c1, c1, kernel_size=3, stride=1, padding=1)
        self.conv2a = nn.Conv2d(c1, c2, kernel_size=3, stride=1, padding=1)
        self.conv2b = nn.Conv2d(c2, c2, kernel_size=3, stride=1, padding=1)
        self.conv3a = nn.Conv2d(c2, c3, kernel_size=3, stride=1, padding=1)
        self.conv3b = nn.Conv2d(c3, c3, kernel_size=3, stride=1, padding=1)
        self.conv4a = nn.Conv2d(c3, c4, kernel_size=3, stride=1, padding=1)
        self.conv4b = nn.Conv2d(c4, c4, kernel_size=3, stride=1, padding=1)
        # Detector head: 64 positions of an 8x8 cell + 1 dustbin.
        self.convPa = nn.Conv2d(c4, c5, kernel_size=3, stride=1, padding=1)
        self.convPb = nn.Conv2d(c5, CELL * CELL + 1, kernel_size=1, stride=1, padding=0)
        # Descriptor head.
        self.convDa = nn.Conv2d(c4, c5, kernel_size=3, stride=1, padding=1)
        self.convDb = nn.Conv2d(c5, self.conf["descriptor_dim"], kernel_size=1, stride=1, padding=0)

    # ------------------------------------------------------------------ network
    def forward_raw(self, image: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The bare network: B x 1 x H x W (H, W multiples of 8) -> (logits B x 65 x H/8 x W/8,
        raw descriptors B x 256 x H/8 x W/8). No softmax, no normalisation.

        With ``backbone_precision: bfloat16`` the shared encoder runs under autocast and the two
        heads in float32 on its output: the detector's logits decide near-ties in the NMS, and
        in bfloat16 they moved half of the keypoints by a pixel or more (docs/features.md)."""
        low = self.conf["backbone_precision"] == "bfloat16"
        with torch.autocast(image.device.type, dtype=torch.bfloat16, enabled=low):
            x = self._first_block(image)
            x = self.relu(self.conv2a(x))
            x = self.pool(self.relu(self.conv2b(x)))
            x = self.relu(self.conv3a(x))
            x = self.pool(self.relu(self.conv3b(x)))
            x = self.relu(self.conv4a(x))
            x = self.relu(self.conv4b(x))
        if low:
            x = x.float()
        logits = self.convPb(self.relu(self.convPa(x)))
        descriptors = self.convDb(self.relu(self.convDa(x)))
        return logits, descriptors

    def _first_block(self, image: torch.Tensor) -> torch.Tensor:
        """conv1a, conv1b and the first pool; on the CPU in stripes of rows whose activations stay under
        :data:`STRIPE_BYTES`.

        Why: at 640x480 each of these activations is 78 MB. glibc serves a thread other than the
        main one from heaps of at most 64 MB, so the extraction threads got every such block as
        fresh pages (~40,000 page faults per forward even with ``cpu_allocator: retain``). A
        stripe reads two rows above and below it (the two 3x3 convolutions' reach) and keeps only
        its own rows: the result is the same as the whole image's (``test_striped_first_block_*``).
        """
        b, _, h, w = image.shape
        rows = STRIPE_BYTES // max(1, b * self.conv1a.out_channels * w * image.element_size()) // 2 * 2
        if image.device.type != "cpu" or rows >= h or rows < 2:
            return self.pool(self.relu(self.conv1b(self.relu(self.conv1a(image)))))
        stripes = []
        for r0 in range(0, h, rows):
            r1 = min(h, r0 + rows)
            a0, a1 = max(0, r0 - 2), min(h, r1 + 2)
            x = self.relu(self.conv1b(self.relu(self.conv1a(image[:, :, a0:a1]))))
            stripes.append(self.pool(x[:, :, r0 - a0 : r1 - a0]))
        return torch.cat(stripes, dim=2)

    def dense(self, image: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Full-resolution score map B x H x W (probabilities) and the unit-norm coarse
        descriptor map B x 256 x H/8 x W/8. H and W must be multiples of 8."""
        logits, descriptors = self.forward_raw(image)
        with serial_on_cpu(image.device):
            return self._dense_from_raw(logits, descriptors)

    @staticmethod
    def _dense_from_raw(logits: torch.Tensor, descriptors: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        prob = logits.softmax(dim=1)[:, :-1]  # drop the dustbin
        scores = F.pixel_shuffle(prob, CELL).squeeze(1)  # channel a*8+b -> pixel (8i+a, 8j+b)
        norm_sq = (descriptors * descriptors).sum(dim=1, keepdim=True).clamp_min(1e-24)
        return scores, descriptors * torch.rsqrt(norm_sq)  # = F.normalize, ~3x cheaper on CPU

    # ------------------------------------------------------------------ extraction
    def forward(self, data: dict) -> dict:
        """``data["image"]``: B x 1 x H x W float in [0, 1]; any H, W (padded to a multiple of 8).

        Returns lists (one entry per image) under ``keypoints`` (N x 2, x/y pixels),
        ``keypoint_scores`` (N) and ``descriptors`` (N x 256), strongest keypoint first.
        """
        image = data["image"]
        if image.dim() != 4 or image.shape[1] != 1:
            raise ValueError(f"expected a B x 1 x H x W image tensor, got shape {tuple(image.shape)}")
        b, _, h, w = image.shape
        pad_h, pad_w = (-h) % CELL, (-w) % CELL
        if pad_h or pad_w:
            with serial_on_cpu(image.device):
                image = F.pad(image, (0, pad_w, 0, pad_h), mode="replicate")
        logits, raw_descriptors = self.forward_raw(image)
        with serial_on_cpu(image.device):
            scores, descriptor_map = self._dense_from_raw(logits, raw_descriptors)
            return self._select(scores[:, :h, :w], descriptor_map)

    def _select(self, scores: torch.Tensor, descriptor_map: torch.Tensor) -> dict:
        """NMS, threshold, border removal, top-k and descriptor sampling on B x H x W scores."""
        b, h, w = scores.shape
        conf = self.conf
        keep = max_pool_nms(scores, conf["nms_radius"]) & (scores > conf["keypoint_threshold"])
        r = conf["remove_borders"]
        if r > 0:
            keep[:, :r] = False
            keep[:, h - r :] = False
            keep[:, :, :r] = False
            keep[:, :, w - r :] = False

        bi, yi, xi = torch.nonzero(keep, as_tuple=True)
        all_scores = scores[bi, yi, xi]
        counts = torch.bincount(bi, minlength=b).tolist()
        out: dict[str, list[torch.Tensor]] = {"keypoints": [], "keypoint_scores": [], "descriptors": []}
        start = 0
        for i, n in enumerate(counts):
            s = all_scores[start : start + n]
            xy = torch.stack([xi[start : start + n], yi[start : start + n]], dim=1)
            start += n
            k = conf["max_keypoints"]
            if 0 <= k < n:
                s, order = torch.topk(s, k, sorted=True)
            else:
                s, order = torch.sort(s, descending=True, stable=True)
            xy = xy[order].to(scores.dtype)
            desc = sample_descriptors(xy, descriptor_map[i : i + 1], conf["descriptor_sampling"])
            out["keypoints"].append(xy)
            out["keypoint_scores"].append(s)
            out["descriptors"].append(desc)
        return out
