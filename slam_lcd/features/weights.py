"""Finding, downloading and loading SuperPoint weights.

Resolution order (first hit wins):

1. an explicit path (``--weights PATH`` / ``FeaturesConfig.weights``);
2. ``$SLAM_LCD_SUPERPOINT_WEIGHTS``;
3. ``superpoint_v1.pth`` in the user cache directory (``$SLAM_LCD_CACHE_DIR`` or
   ``~/.cache/slam-lcd``);
4. a download of the official Magic Leap release, checked against its sha256, into that
   cache directory (written atomically, so an interrupted download leaves nothing). The
   download address is ``features.weights_url``, else ``$SLAM_LCD_SUPERPOINT_URL`` (a mirror;
   tests point it at a closed loopback port to play "offline"), else the official release.

An explicit path or environment variable that points nowhere is an error, never silently
skipped: a user who names a file means that file. "No weights anywhere and no download"
is its own error (:class:`WeightsUnavailableError`), so that ``slam-lcd demo`` can fall
back to ORB on exactly that case and nothing else.
"""
from __future__ import annotations

import hashlib
import os
import urllib.error
import urllib.request
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from ..errors import DownloadError, WeightsError
from ..files.atomic import atomic_path
from ..files.hashing import sha256_of
from ..runtime.quiet import one_line
from .config import SUPERPOINT_SHA256, SUPERPOINT_URL

if TYPE_CHECKING:
    import torch

ENV_WEIGHTS = "SLAM_LCD_SUPERPOINT_WEIGHTS"
ENV_CACHE = "SLAM_LCD_CACHE_DIR"
ENV_URL = "SLAM_LCD_SUPERPOINT_URL"
WEIGHTS_NAME = "superpoint_v1.pth"


class WeightsUnavailableError(WeightsError):
    """No weights file anywhere it is looked for, and none could be downloaded (offline,
    HTTP error, or downloading disabled). A named file that is missing is *not* this error."""


class WeightsDownloadError(WeightsError, DownloadError):
    """The download of the weights failed (offline, HTTP error, checksum mismatch)."""


class WeightsOfflineError(WeightsDownloadError, WeightsUnavailableError):
    """The download could not reach the file (no network, refused connection, HTTP error)."""


def download_url(url: str | None = None) -> str:
    """Where the weights are downloaded from: ``url``, ``$SLAM_LCD_SUPERPOINT_URL``, the official release."""
    return url or os.environ.get(ENV_URL) or SUPERPOINT_URL


def cache_dir(override: str | Path | None = None) -> Path:
    """The user cache directory: ``override``, ``$SLAM_LCD_CACHE_DIR`` or ``~/.cache/slam-lcd``."""
    if override:
        return Path(override).expanduser()
    env = os.environ.get(ENV_CACHE)
    if env:
        return Path(env).expanduser()
    return Path.home() / ".cache" / "slam-lcd"


def download_weights(url: str, target: Path, sha256: str | None, timeout: float = 30.0) -> Path:
    """Fetch ``url`` into ``target`` atomically; refuse it if its sha256 differs."""
    target = Path(target)
    try:
        with atomic_path(target) as tmp:
            h = hashlib.sha256()
            with urllib.request.urlopen(url, timeout=timeout) as resp, open(tmp, "wb") as fh:
                while block := resp.read(1 << 20):
                    h.update(block)
                    fh.write(block)
            digest = h.hexdigest()
            if sha256 and digest != sha256.lower():
                raise WeightsDownloadError(
                    f"checksum mismatch for download from {url}: got sha256 {digest}, expected {sha256}; "
                    "file discarded",
                    target,
                )
    except (urllib.error.URLError, OSError, ValueError) as e:
        reason = getattr(e, "reason", None) or e
        raise WeightsOfflineError(
            f"SuperPoint weights not found locally and the download from {url} failed ({reason}). "
            f"Put the official weights file at {target}, or pass --weights PATH, "
            f"or set ${ENV_WEIGHTS} (or use the ORB baseline: --features orb)",
            target,
        ) from None
    return target


def resolve_weights(
    path: str | Path | None = None,
    *,
    cache: str | Path | None = None,
    url: str | None = None,
    sha256: str | None = SUPERPOINT_SHA256,
    allow_download: bool = True,
) -> Path:
    """Return the path of a SuperPoint weights file (see the module docstring for the order)."""
    if path:
        p = Path(path).expanduser()
        if not p.is_file():
            raise WeightsError("SuperPoint weights file not found (given with --weights / features.weights): leave "
                               "them out for the cached or downloaded weights, or use the ORB baseline: "
                               "--features orb", p)
        return p
    env = os.environ.get(ENV_WEIGHTS)
    if env:
        p = Path(env).expanduser()
        if not p.is_file():
            raise WeightsError(f"SuperPoint weights file named by ${ENV_WEIGHTS} not found: unset it for the "
                               "cached or downloaded weights, or use the ORB baseline: --features orb", p)
        return p
    target = cache_dir(cache) / WEIGHTS_NAME
    if target.is_file():
        return target
    if not allow_download:
        raise WeightsUnavailableError(
            f"SuperPoint weights not found and downloading is disabled. Put the official weights file "
            f"({WEIGHTS_NAME}) at {target}, or pass --weights PATH, or set ${ENV_WEIGHTS} "
            f"(or use the ORB baseline: --features orb)",
            target,
        )
    return download_weights(download_url(url), target, sha256)


def _unwrap(obj):
    """Accept a bare state dict or the common wrappers ({'state_dict': ...}, 'module.' prefixes)."""
    if isinstance(obj, dict):
        for key in ("state_dict", "model_state_dict", "model"):
            if key in obj and isinstance(obj[key], dict):
                obj = obj[key]
                break
    if isinstance(obj, dict) and obj and all(isinstance(k, str) for k in obj):
        if all(k.startswith("module.") for k in obj):
            obj = {k[len("module.") :]: v for k, v in obj.items()}
    return obj


def _check_checkpoint_container(path: Path) -> None:
    """A PyTorch checkpoint is a zip archive (``torch.save``) or, in the legacy format, a pickle
    (its first byte 0x80); anything else (a text file, an image) is said to be no checkpoint,
    before torch reads its bytes as pickle opcodes."""
    import zipfile

    try:
        with open(path, "rb") as fh:
            head = fh.read(4)
    except OSError as e:
        raise WeightsError(f"cannot read the weights file ({e.strerror or e})", path) from None
    if not head:
        raise WeightsError("is empty, not a PyTorch checkpoint", path)
    if head[:1] != b"\x80" and head != b"PK\x03\x04" and not zipfile.is_zipfile(path):  # a cut zip: torch says
        kind = "a text file" if _looks_like_text(path) else "neither a zip archive nor a pickle"
        raise WeightsError(f"is not a PyTorch checkpoint ({kind}); give a file written by torch.save", path)


def _looks_like_text(path: Path) -> bool:
    with open(path, "rb") as fh:
        chunk = fh.read(4096)
    try:
        chunk.decode("utf-8")
    except UnicodeDecodeError:
        return False
    return b"\x00" not in chunk


def load_state_dict_checked(model: torch.nn.Module, path: str | Path) -> None:
    """Load ``path`` into ``model`` with ``strict=True``; any problem is a one-line WeightsError."""
    import torch  # here, not at import: `slam-lcd weights` and the resolver need no torch

    path = Path(path)
    _check_checkpoint_container(path)
    try:
        obj = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as e:  # corrupt zip/pickle, truncated file, not a torch file
        if "weights only load failed" in str(e).lower():  # torch's long, ANSI-coloured advice: ours instead
            raise WeightsError("holds pickled Python objects besides tensors, which slam-lcd refuses to load "
                               "(weights_only=True); save a plain state dict: torch.save(model.state_dict(), path)",
                               path) from None
        first = str(e).strip().splitlines()[0] if str(e).strip() else ""
        raise WeightsError(f"not a readable PyTorch weights file ({type(e).__name__}: {one_line(first, 160)})",
                           path) from None
    sd = _unwrap(obj)
    if not isinstance(sd, dict) or not all(isinstance(v, torch.Tensor) for v in sd.values()):
        raise WeightsError(f"does not hold a state dict of tensors (found {type(sd).__name__})", path)
    expected = model.state_dict()
    missing = [k for k in expected if k not in sd]
    unexpected = [k for k in sd if k not in expected]
    wrong = [
        f"{k} has shape {tuple(sd[k].shape)} in the file but {tuple(v.shape)} in SuperPoint"
        for k, v in expected.items()
        if k in sd and tuple(sd[k].shape) != tuple(v.shape)
    ]
    problems = []
    if wrong:
        problems.append("; ".join(wrong[:3]) + (f" (+{len(wrong) - 3} more)" if len(wrong) > 3 else ""))
    if missing:
        problems.append(f"missing keys {missing[:4]}" + (f" (+{len(missing) - 4} more)" if len(missing) > 4 else ""))
    if unexpected:
        problems.append(
            f"unexpected keys {unexpected[:4]}" + (f" (+{len(unexpected) - 4} more)" if len(unexpected) > 4 else "")
        )
    if problems:
        raise WeightsError("not SuperPoint weights: " + "; ".join(problems), path)
    bad = [k for k, v in sd.items() if not torch.isfinite(v).all()]
    if bad:
        raise WeightsError(f"weights contain NaN/inf values in {bad[:4]}", path)
    model.load_state_dict({k: v.float() for k, v in sd.items()}, strict=True)


# --------------------------------------------------------------------------- report (`slam-lcd weights`)
@dataclass
class WeightsCandidate:
    """One place the resolver looks, in order, and what is there."""

    source: str  # how it is named: the flag, the environment variable, the cache, the download
    location: str  # a path, or the download URL
    state: str  # 'not given', 'found', 'missing', 'would download', ...


@dataclass
class WeightsReport:
    candidates: list[WeightsCandidate]
    used: Path | None  # the file a run would load now (None: a download is needed)
    error: str | None = None  # why there is no file (a named file that is missing)
    sha256: str | None = None

    @property
    def official(self) -> bool:
        return self.sha256 == SUPERPOINT_SHA256


def weights_report(
    path: str | Path | None = None,
    *,
    cache: str | Path | None = None,
    url: str | None = None,
    allow_download: bool = True,
) -> WeightsReport:
    """Where weights are looked for (the order of :func:`resolve_weights`) and which file is used; no download."""
    env = os.environ.get(ENV_WEIGHTS)
    target = cache_dir(cache) / WEIGHTS_NAME
    rows = [
        WeightsCandidate("--weights / features.weights", str(Path(path).expanduser()) if path else "-",
                         "not given" if not path else ("found" if Path(path).expanduser().is_file() else "missing")),
        WeightsCandidate(f"${ENV_WEIGHTS}", env or "-",
                         "not set" if not env else ("found" if Path(env).expanduser().is_file() else "missing")),
        WeightsCandidate("cache", str(target), "found" if target.is_file() else "missing"),
        WeightsCandidate("download", download_url(url), "enabled" if allow_download else "disabled"),
    ]
    used = error = None
    for k, row in enumerate(rows[:3]):
        if row.state == "found":
            used = Path(row.location)
            break
        if row.state == "missing" and k < 2:  # a named file that is missing stops the search (never skipped)
            error = f"{row.source} names {row.location}, which does not exist"
            break
    return WeightsReport(rows, used, error, sha256_of(used) if used is not None else None)
