"""Configuration section `features` (owned by :mod:`slam_lcd.features`)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from ..value_range import ranged

# Official Magic Leap release of the SuperPoint weights (MIT-style research licence: the user
# downloads them; the package never ships them).
SUPERPOINT_URL = "https://github.com/magicleap/SuperPointPretrainedNetwork/raw/master/superpoint_v1.pth"
SUPERPOINT_SHA256 = "52b6708629640ca883673b5d5c097c4ddad37d8048b33f09c8ca0d69db12c40e"


@dataclass
class FeaturesConfig:
    # which extractor: 'superpoint' (learned, float 256-D) or 'orb' (OpenCV, binary 32-byte)
    kind: Literal["superpoint", "orb"] = "superpoint"
    # SuperPoint weights file; None = $SLAM_LCD_SUPERPOINT_WEIGHTS, then the cache dir, then download
    weights: str | None = None
    # where inference runs: 'auto' picks CUDA when available, else CPU
    device: Literal["auto", "cpu", "cuda"] = "auto"
    # non-maximum suppression radius in pixels (window of 2r+1)
    nms_radius: int = ranged(4, "[0, inf)")
    # minimum detector confidence (softmax probability) of a keypoint
    keypoint_threshold: float = ranged(0.015, "[0, 1)")
    # keypoints closer than this many pixels to the image border are dropped
    remove_borders: int = ranged(4, "[0, inf)")
    # keep the highest-scoring keypoints only; -1 keeps all
    max_keypoints: int = ranged(1000, "-1 or [1, inf)")
    # extract on a copy whose longest side is at most this many pixels (aspect kept, area
    # interpolation; hloc's resize_max); keypoints are reported in the full image's pixels, so
    # geometry downstream is unchanged. SuperPoint's cost falls with the pixel count (a 640x480
    # image at 320: about a quarter). None = the image as it is (docs/presets.md). At least 32: below
    # that SuperPoint's 8-pixel cells and borders leave little image
    resize_max: int | None = ranged(None, "[32, inf)")
    # interpolation of the 1/8-resolution descriptor map at keypoints
    descriptor_sampling: Literal["bilinear", "bicubic"] = "bilinear"
    # images per network forward in extract_batch
    batch_size: int = ranged(8, "[1, inf)")
    # CPU inference: 'retain' tells glibc to keep freed memory for the next forward pass
    # (no page faults on SuperPoint's large activations, ~30% of CPU time otherwise);
    # 'system' leaves malloc as the environment set it
    cpu_allocator: Literal["retain", "system"] = "retain"
    # CPU inference in channels-last (NHWC) memory layout: oneDNN's faster convolution path
    # (about 30% less CPU time per 640x480 forward here; outputs differ by ~1e-5)
    cpu_channels_last: bool = True
    # arithmetic of SuperPoint's shared encoder: 'float32' (the reference) or 'bfloat16' (autocast;
    # the detector and descriptor heads stay float32). On CPUs with AMX / AVX512-BF16 a 640x480
    # forward takes ~0.43x the time; 95% of the keypoints stay within 1 px, descriptor cosine 0.9998
    # (docs/features.md). Elsewhere bfloat16 is emulated and slower (the log warns once). 'auto':
    # bfloat16 where the device computes it natively (oneDNN's check on CPU; the GPU's own), else float32
    precision: Literal["auto", "float32", "bfloat16"] = "auto"
    # ORB baseline: number of features, pyramid scale factor and levels, FAST threshold
    orb_n_features: int = ranged(1000, "[1, inf)")
    orb_scale_factor: float = ranged(1.2, "(1, inf)")
    orb_n_levels: int = ranged(8, "[1, inf)")
    orb_fast_threshold: int = ranged(20, "[0, 255]")
    # user cache directory (weights, features); None = $SLAM_LCD_CACHE_DIR or ~/.cache/slam-lcd
    cache_dir: str | None = None
    # store extracted features on disk keyed by log, topic, stamp and extractor config
    feature_cache: bool = True
    # allow downloading the official weights when none are found locally
    allow_download: bool = True
    # download source of the SuperPoint weights; None = $SLAM_LCD_SUPERPOINT_URL, else the
    # official release (SUPERPOINT_URL); the download is checked against weights_sha256
    weights_url: str | None = None
    weights_sha256: str = SUPERPOINT_SHA256
