"""SuperPoint network: architecture, weight loading and the extraction contract."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from slam_lcd.errors import SlamLcdError, WeightsError
from slam_lcd.features import FeaturesConfig, SuperPoint, SuperPointExtractor, load_extractor
from slam_lcd.features.superpoint import max_pool_nms, sample_descriptors
from slam_lcd.features.weights import load_state_dict_checked

from support.module_files import random_extractor

# The official Magic Leap superpoint_v1.pth layout: (name, shape) of every tensor.
OFFICIAL_LAYOUT = {
    "conv1a": (64, 1, 3, 3), "conv1b": (64, 64, 3, 3),
    "conv2a": (64, 64, 3, 3), "conv2b": (64, 64, 3, 3),
    "conv3a": (128, 64, 3, 3), "conv3b": (128, 128, 3, 3),
    "conv4a": (128, 128, 3, 3), "conv4b": (128, 128, 3, 3),
    "convPa": (256, 128, 3, 3), "convPb": (65, 256, 1, 1),
    "convDa": (256, 128, 3, 3), "convDb": (256, 256, 1, 1),
}


def random_model(seed=0, **conf) -> SuperPoint:
    torch.manual_seed(seed)
    return SuperPoint(conf).eval()


def textured_image(h=120, w=160, seed=0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    img = np.zeros((h, w), np.float32)
    for _ in range(40):  # random rectangles give corners
        x0, y0 = rng.integers(0, w - 10), rng.integers(0, h - 10)
        img[y0 : y0 + rng.integers(5, 30), x0 : x0 + rng.integers(5, 30)] = rng.uniform(0, 1)
    return img


def test_parameter_names_and_shapes_are_the_official_layout():
    sd = SuperPoint().state_dict()
    expected = {}
    for name, shape in OFFICIAL_LAYOUT.items():
        expected[f"{name}.weight"] = shape
        expected[f"{name}.bias"] = (shape[0],)
    assert {k: tuple(v.shape) for k, v in sd.items()} == expected


def test_shared_checkpoint_loads_strict(superpoint_weights):
    sd = torch.load(superpoint_weights, map_location="cpu", weights_only=True)
    model = SuperPoint()
    model.load_state_dict(sd, strict=True)  # the plain PyTorch path works
    load_state_dict_checked(SuperPoint(), superpoint_weights)  # and the checked one


def test_corrupt_weights_file_is_a_one_line_error(tmp_path, superpoint_weights):
    bad = tmp_path / "truncated.pth"
    bad.write_bytes(superpoint_weights.read_bytes()[:100_000])
    with pytest.raises(WeightsError) as e:
        load_state_dict_checked(SuperPoint(), bad)
    msg = str(e.value)
    assert "\n" not in msg and str(bad) in msg and "not a readable PyTorch weights file" in msg

    junk = tmp_path / "junk.pth"
    junk.write_text("hello, I am not a checkpoint")
    with pytest.raises(WeightsError, match="junk.pth"):
        load_state_dict_checked(SuperPoint(), junk)


def test_wrong_shaped_weights_name_the_tensor_and_both_shapes(tmp_path):
    sd = SuperPoint().state_dict()
    sd["conv1a.weight"] = torch.zeros(64, 3, 3, 3)  # an RGB-input variant
    p = tmp_path / "rgb_superpoint.pth"
    torch.save(sd, p)
    with pytest.raises(WeightsError) as e:
        load_state_dict_checked(SuperPoint(), p)
    msg = str(e.value)
    assert "\n" not in msg and str(p) in msg
    assert "conv1a.weight" in msg and "(64, 3, 3, 3)" in msg and "(64, 1, 3, 3)" in msg


def test_missing_and_unexpected_keys_are_named(tmp_path):
    sd = SuperPoint().state_dict()
    del sd["convDb.bias"]
    sd["bn1.running_mean"] = torch.zeros(64)
    p = tmp_path / "other.pth"
    torch.save(sd, p)
    with pytest.raises(WeightsError) as e:
        load_state_dict_checked(SuperPoint(), p)
    msg = str(e.value)
    assert "convDb.bias" in msg and "bn1.running_mean" in msg and "\n" not in msg


def test_missing_explicit_weights_file_is_an_error(tmp_path):
    with pytest.raises(WeightsError, match="nope.pth"):
        load_extractor(FeaturesConfig(weights=str(tmp_path / "nope.pth")), device="cpu")


def test_score_map_is_depth_to_space_of_the_cell_softmax():
    """The pixel-shuffle score map equals the paper's reshape/transpose depth-to-space."""
    model = random_model()
    x = torch.rand(2, 1, 48, 64)
    with torch.inference_mode():
        logits, _ = model.forward_raw(x)
        scores, _ = model.dense(x)
    prob = logits.softmax(1)[:, :64]  # B, 64, Hc, Wc
    b, _, hc, wc = prob.shape
    ref = prob.permute(0, 2, 3, 1).reshape(b, hc, wc, 8, 8).permute(0, 1, 3, 2, 4).reshape(b, hc * 8, wc * 8)
    torch.testing.assert_close(scores, ref)


def test_descriptor_at_cell_centre_is_that_cells_descriptor():
    dmap = torch.nn.functional.normalize(torch.randn(1, 256, 6, 10), dim=1)
    i, j = 4, 7
    kp = torch.tensor([[8 * j + 3.5, 8 * i + 3.5]])
    for mode in ("bilinear", "bicubic"):
        d = sample_descriptors(kp, dmap, mode)
        torch.testing.assert_close(d[0], dmap[0, :, i, j], atol=1e-5, rtol=0)


def test_nms_keeps_only_window_maxima():
    torch.manual_seed(1)
    s = torch.rand(1, 40, 50)
    keep = max_pool_nms(s, 4)
    ys, xs = torch.nonzero(keep[0], as_tuple=True)
    for y, x in zip(ys.tolist(), xs.tolist(), strict=True):
        win = s[0, max(0, y - 4) : y + 5, max(0, x - 4) : x + 5]
        assert s[0, y, x] == win.max()
    # every window maximum survives
    y, x = divmod(int(s[0].argmax()), 50)
    assert keep[0, y, x]


@pytest.mark.parametrize("h,w", [(120, 160), (117, 155), (61, 203)])
def test_extraction_contract_on_any_size(h, w):
    ex = random_extractor(max_keypoints=200, keypoint_threshold=0.0)
    img = textured_image(h, w)
    f = ex.extract(img)
    assert f.image_size == (w, h) and f.kind == "superpoint"
    n = len(f)
    assert 0 < n <= 200
    assert f.keypoints.dtype == np.float32 and f.keypoints.shape == (n, 2)
    assert f.scores.dtype == np.float32 and f.descriptors.dtype == np.float32
    assert f.descriptors.shape == (n, 256)
    np.testing.assert_allclose(np.linalg.norm(f.descriptors, axis=1), 1.0, atol=1e-5)
    r = ex.conf.remove_borders
    assert f.keypoints[:, 0].min() >= r and f.keypoints[:, 0].max() <= w - 1 - r
    assert f.keypoints[:, 1].min() >= r and f.keypoints[:, 1].max() <= h - 1 - r
    assert np.all(np.diff(f.scores) <= 0)  # strongest first


def test_threshold_and_max_keypoints_are_respected():
    img = textured_image()
    all_kp = random_extractor(max_keypoints=-1, keypoint_threshold=0.0).extract(img)
    top = random_extractor(max_keypoints=50, keypoint_threshold=0.0).extract(img)
    assert len(all_kp) > 50 and len(top) == 50
    np.testing.assert_array_equal(top.keypoints, all_kp.keypoints[:50])
    thr = float(np.median(all_kp.scores))
    some = random_extractor(max_keypoints=-1, keypoint_threshold=thr).extract(img)
    assert np.all(some.scores > thr) and len(some) == int((all_kp.scores > thr).sum())


def test_deterministic_batch_equals_single_and_input_types_agree():
    ex = random_extractor(max_keypoints=300, keypoint_threshold=0.0, batch_size=3)
    imgs = [textured_image(seed=s) for s in range(4)] + [textured_image(101, 157, seed=9)]
    singles = [ex.extract(im) for im in imgs]
    again = [ex.extract(im) for im in imgs]
    batch = ex.extract_batch(imgs)
    for a, b, c in zip(singles, again, batch, strict=True):
        # the same call twice: bit-identical
        np.testing.assert_array_equal(a.keypoints, b.keypoints)
        np.testing.assert_array_equal(a.descriptors, b.descriptors)
        # batched: the convolution backend may pick another algorithm for another batch size
        # (seen with 16 threads), so near-equal scores may swap; compare as sets
        assert a.image_size == c.image_size and len(a) == len(c)
        pos = {tuple(k): i for i, k in enumerate(c.keypoints.tolist())}
        common = [(i, pos[tuple(k)]) for i, k in enumerate(a.keypoints.tolist()) if tuple(k) in pos]
        assert len(common) >= 0.97 * len(a)
        ia, ic = np.array(common).T
        np.testing.assert_allclose(a.descriptors[ia], c.descriptors[ic], atol=1e-4)
        np.testing.assert_allclose(a.scores[ia], c.scores[ic], atol=1e-5)
    u8 = (imgs[0] * 255).round().astype(np.uint8)
    rgb = np.repeat(u8[:, :, None], 3, axis=2)
    fu, fr = ex.extract(u8), ex.extract(rgb)
    np.testing.assert_array_equal(fu.keypoints, fr.keypoints)


def test_bad_inputs_and_settings_are_typed_errors():
    ex = random_extractor()
    with pytest.raises(SlamLcdError):
        ex.extract(np.zeros((4, 5, 6, 7), np.uint8))
    with pytest.raises(SlamLcdError):
        random_extractor(max_keypoints=0)
    with pytest.raises(SlamLcdError, match="kind"):
        load_extractor(FeaturesConfig(kind="sift"))  # type: ignore[arg-type]


def test_real_frame_extraction_with_shared_weights(superpoint_weights, shared_data):
    import cv2

    path = sorted((shared_data / "frames" / "kitti").glob("*.png"))[0]
    img = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    ex = load_extractor(FeaturesConfig(weights=str(superpoint_weights), max_keypoints=1000), device="cpu")
    f = ex.extract(img)
    assert f.image_size == (1241, 376)
    assert 300 <= len(f) <= 1000
    assert f.scores.min() > 0.015


_TRIM_SCRIPT = """
import ctypes
from slam_lcd.features.allocator import heap_free_bytes, retain_freed_memory, trim_when_fragmented
assert retain_freed_memory()
libc = ctypes.CDLL("libc.so.6")
libc.malloc.restype = ctypes.c_void_p
libc.free.argtypes = [ctypes.c_void_p]
def rss_mb():
    return next(int(l.split()[1]) for l in open("/proc/self/status") if l.startswith("VmRSS")) >> 10
big, small = [], []
for _ in range(300):  # 1 MB blocks between small ones that live on: freeing the big ones leaves holes
    p = libc.malloc(1 << 20)
    ctypes.memset(p, 1, 1 << 20)
    big.append(p)
    small.append(libc.malloc(256))
before = rss_mb()
for p in big:
    libc.free(p)
free = heap_free_bytes() >> 20
held = rss_mb()
early = trim_when_fragmented(limit=100 << 20, min_calls=3)  # the first call: too soon
first, again = trim_when_fragmented(limit=100 << 20, min_calls=2), trim_when_fragmented(limit=100 << 20, min_calls=1)
print(free, before, held, rss_mb(), int(early), int(first), int(again))
"""


@pytest.mark.skipif(not __import__("sys").platform.startswith("linux"), reason="glibc malloc_trim is Linux-only")
def test_heap_holes_are_returned_once_they_grow_past_the_limit():
    """'retain' keeps freed memory, so holes between long-lived blocks stay resident; past the limit (and
    not sooner than ``min_calls`` calls) the pages go back to the system once, and not again until the
    holes grow by the limit once more."""
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-c", _TRIM_SCRIPT], capture_output=True, text=True, check=True)
    free, before, held, after, early, first, again = map(int, out.stdout.split())
    print(f"\n300 MB of holes: {free} MB free in the heap; "
          f"RSS {before} -> {held} (freed, kept) -> {after} MB (trimmed)")
    assert free >= 290 and held > before - 30  # kept resident: 'retain'
    assert early == 0 and first == 1 and again == 0  # spaced out; then only once the holes grow again
    assert after < held - 250


@pytest.mark.parametrize("stripe_rows", [2, 6, 40])
def test_striped_first_block_equals_the_whole_image(monkeypatch, stripe_rows):
    """The first block in stripes of rows (each reads 2 rows of its neighbours) gives the whole image's result."""
    import slam_lcd.features.superpoint as sp

    ex = random_extractor(seed=3)
    img = textured_image(h=120, w=168, seed=5)
    x = torch.from_numpy(img)[None, None].contiguous(memory_format=torch.channels_last)
    with torch.inference_mode():
        whole = ex.model._first_block(x)
        monkeypatch.setattr(sp, "STRIPE_BYTES", stripe_rows * 64 * 168 * 4)
        striped = ex.model._first_block(x)
        f = ex.extract(img)
        monkeypatch.setattr(sp, "STRIPE_BYTES", 1 << 40)
        g = ex.extract(img)
    assert striped.shape == whole.shape == (1, 64, 60, 84)
    torch.testing.assert_close(striped, whole, rtol=0, atol=1e-5)
    np.testing.assert_array_equal(f.keypoints, g.keypoints)
    np.testing.assert_allclose(f.descriptors, g.descriptors, atol=1e-5)


def test_bfloat16_encoder_keeps_the_keypoints_and_descriptors(superpoint_weights, shared_data):
    """features.precision bfloat16: real frames give (nearly) the float32 features; heads stay float32.

    Three frames of each source (KITTI, TUM, corridor) where the CPU computes bfloat16 in
    hardware; one of each where oneDNN emulates it (~5 s per frame on an AVX2-only CPU)."""
    import cv2

    from slam_lcd.features.superpoint_extractor import bfloat16_is_native

    per_source = 3 if bfloat16_is_native(torch.device("cpu")) else 1
    frames = [p for d in ("kitti", "tum_fr2_desk")
              for p in sorted((shared_data / "frames" / d).glob("*.png"))[:per_source]]
    frames += sorted((shared_data / "rtabmap_corridor").glob("*.jpg"))[:per_source]
    assert len(frames) == 3 * per_source
    ex32, ex16 = (load_extractor(FeaturesConfig(weights=str(superpoint_weights), precision=p, feature_cache=False),
                                 device="cpu") for p in ("float32", "bfloat16"))
    assert "backbone_precision" not in ex32.identity()  # float32 caches from before the option keep their key
    assert ex16.identity()["backbone_precision"] == "bfloat16" and ex16.fingerprint != ex32.fingerprint
    with torch.inference_mode():
        logits, desc = ex16.model.forward_raw(torch.rand(1, 1, 64, 80))
    assert logits.dtype == desc.dtype == torch.float32
    near, cosine = [], []
    for path in frames:
        img = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        a, b = ex32.extract(img), ex16.extract(img)
        assert abs(len(a) - len(b)) <= 0.05 * len(a)
        d = np.linalg.norm(a.keypoints[:, None] - b.keypoints[None], axis=2)
        j = d.argmin(axis=1)
        ok = d[np.arange(len(j)), j] < 1.0
        near.append(ok.mean())
        cosine.append(np.median(np.sum(a.descriptors[ok] * b.descriptors[j[ok]], axis=1)))
    print(f"\nbfloat16 encoder: keypoints within 1 px {np.mean(near):.3f} (min {np.min(near):.3f}), "
          f"descriptor cosine median {np.median(cosine):.5f}")
    assert np.mean(near) > 0.9 and np.min(near) > 0.8
    assert np.min(cosine) > 0.999
    with pytest.raises(ValueError, match="backbone_precision"):
        SuperPoint(backbone_precision="float16")


def test_device_choice():
    from slam_lcd.errors import ConfigError

    assert random_extractor().device.type == "cpu"
    conf = FeaturesConfig()
    if not torch.cuda.is_available():
        with pytest.raises(ConfigError, match="cuda"):
            SuperPointExtractor(conf, device="cuda", model=SuperPoint())
        auto = SuperPointExtractor(conf, device="auto", model=SuperPoint())
        assert auto.device.type == "cpu"
    with pytest.raises(ConfigError, match="device"):
        SuperPointExtractor(conf, device="tpu", model=SuperPoint())


_FAULTS_SCRIPT = """
import resource, sys, numpy as np, torch
from concurrent.futures import ThreadPoolExecutor
from slam_lcd.features import FeaturesConfig, SuperPoint, SuperPointExtractor
from slam_lcd.features.allocator import allocator_state
conf = FeaturesConfig(cpu_allocator=sys.argv[1])
torch.manual_seed(0)
ex = SuperPointExtractor(conf, device="cpu", model=SuperPoint(SuperPointExtractor.model_conf(conf)))
img = np.random.default_rng(0).random((480, 640)).astype(np.float32)
def faults_per_forward():
    ex.extract(img); ex.extract(img)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(3):
        ex.extract(img)
    return (resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before) // 3
if sys.argv[2] == "main":
    n = faults_per_forward()
else:  # as the pipeline extracts: in a worker thread (its own glibc arena unless limited)
    with ThreadPoolExecutor(max_workers=2) as pool:
        n = pool.submit(faults_per_forward).result()
print(allocator_state(), n)
"""


@pytest.mark.skipif(not __import__("sys").platform.startswith("linux"), reason="glibc mallopt is Linux-only")
@pytest.mark.parametrize("thread", ["main", "worker"])
def test_cpu_allocator_retain_removes_page_faults_of_the_forward_pass(thread):
    """With 'retain' a 640x480 forward reuses the heap's pages, on the main thread and in an extraction thread."""
    import subprocess
    import sys

    faults = {}
    for mode in ("retain", "system"):
        out = subprocess.run([sys.executable, "-c", _FAULTS_SCRIPT, mode, thread], capture_output=True, text=True,
                             check=True)
        state, n = out.stdout.split()
        faults[mode] = int(n)
        assert state == mode
    print(f"\nminor page faults per 640x480 forward ({thread} thread): {faults}")
    assert faults["system"] > 20000  # 78 MB activations mapped afresh each call
    assert faults["retain"] < faults["system"] / 10
