"""Weights resolution: flag > $SLAM_LCD_SUPERPOINT_WEIGHTS > cache dir > checked download."""
from __future__ import annotations

import contextlib
import functools
import hashlib
import http.server
import threading

import pytest

from slam_lcd.errors import DownloadError, WeightsError
from slam_lcd.features import FeaturesConfig, load_extractor, resolve_weights
from slam_lcd.features.weights import (
    ENV_CACHE,
    ENV_URL,
    ENV_WEIGHTS,
    WEIGHTS_NAME,
    WeightsDownloadError,
    WeightsUnavailableError,
    cache_dir,
    weights_report,
)

from support.offline import free_port


@pytest.fixture(autouse=True)
def clean_env(monkeypatch, tmp_path):
    monkeypatch.delenv(ENV_WEIGHTS, raising=False)
    monkeypatch.delenv(ENV_URL, raising=False)
    monkeypatch.setenv(ENV_CACHE, str(tmp_path / "cache"))


@contextlib.contextmanager
def serve_directory(root):
    """A loopback HTTP server on a free port serving ``root``, stopped afterwards."""
    handler = functools.partial(http.server.SimpleHTTPRequestHandler, directory=str(root))

    class Quiet(handler.func):  # type: ignore[misc]
        def log_message(self, *args):
            pass

    srv = http.server.ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(Quiet, directory=str(root)))
    t = threading.Thread(target=srv.serve_forever, daemon=True)
    t.start()
    try:
        yield f"http://127.0.0.1:{srv.server_address[1]}"
    finally:
        srv.shutdown()
        srv.server_close()
        t.join(timeout=5)


def sha(path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_cache_dir_follows_env_and_override(tmp_path, monkeypatch):
    assert cache_dir() == tmp_path / "cache"
    assert cache_dir(tmp_path / "x") == tmp_path / "x"
    monkeypatch.delenv(ENV_CACHE)
    assert cache_dir().parts[-2:] == (".cache", "slam-lcd")


def test_resolution_order(tmp_path, monkeypatch):
    flag = tmp_path / "flag.pth"
    env = tmp_path / "env.pth"
    cached = tmp_path / "cache" / WEIGHTS_NAME
    for p in (flag, env, cached):
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_bytes(b"x")
    monkeypatch.setenv(ENV_WEIGHTS, str(env))
    assert resolve_weights(flag, allow_download=False) == flag
    assert resolve_weights(None, allow_download=False) == env
    monkeypatch.delenv(ENV_WEIGHTS)
    assert resolve_weights(None, allow_download=False) == cached


def test_env_pointing_nowhere_is_an_error(tmp_path, monkeypatch):
    monkeypatch.setenv(ENV_WEIGHTS, str(tmp_path / "gone.pth"))
    with pytest.raises(WeightsError, match="SLAM_LCD_SUPERPOINT_WEIGHTS"):
        resolve_weights(None, allow_download=False)


def test_offline_without_weights_says_where_to_put_the_file(tmp_path):
    target = tmp_path / "cache" / WEIGHTS_NAME
    url = f"http://127.0.0.1:{free_port()}/superpoint_v1.pth"  # nothing listens there
    with pytest.raises(WeightsError) as e:
        resolve_weights(None, url=url, sha256="0" * 64)
    msg = str(e.value)
    assert "\n" not in msg and str(target) in msg and "--weights" in msg and ENV_WEIGHTS in msg
    assert not target.exists()
    with pytest.raises(WeightsError, match="downloading is disabled") as e:
        resolve_weights(None, allow_download=False)
    assert str(target) in str(e.value)


def test_download_from_loopback_server_then_reuse_cache(tmp_path, superpoint_weights):
    with serve_directory(superpoint_weights.parent) as base:
        conf = FeaturesConfig(
            weights_url=f"{base}/{superpoint_weights.name}",
            weights_sha256=sha(superpoint_weights),
            max_keypoints=100,
        )
        ex = load_extractor(conf, device="cpu")
    target = tmp_path / "cache" / WEIGHTS_NAME
    assert ex.weights_path == target and sha(target) == sha(superpoint_weights)
    # server gone: the cached copy is used, no download
    again = resolve_weights(None, url="http://127.0.0.1:9/none", sha256="0" * 64)
    assert again == target
    assert not [p for p in target.parent.iterdir() if p.name != WEIGHTS_NAME]  # no temp leftovers


def test_checksum_mismatch_discards_download(tmp_path, superpoint_weights):
    target = tmp_path / "cache" / WEIGHTS_NAME
    with serve_directory(superpoint_weights.parent) as base:
        with pytest.raises(WeightsDownloadError) as e:
            resolve_weights(None, url=f"{base}/{superpoint_weights.name}", sha256="ab" * 32)
    assert isinstance(e.value, DownloadError) and isinstance(e.value, WeightsError)
    assert "checksum mismatch" in str(e.value) and sha(superpoint_weights) in str(e.value)
    assert not target.exists() and not list(target.parent.iterdir())


def test_download_from_file_url(tmp_path):
    src = tmp_path / "release.bin"
    src.write_bytes(b"pretend weights" * 1000)
    p = resolve_weights(None, url=src.as_uri(), sha256=sha(src))
    assert p == tmp_path / "cache" / WEIGHTS_NAME and p.read_bytes() == src.read_bytes()


def test_http_404_is_a_weights_error(tmp_path):
    with serve_directory(tmp_path) as base:
        with pytest.raises(WeightsError, match="download"):
            resolve_weights(None, url=f"{base}/missing.pth", sha256=None)


def test_unavailable_is_its_own_error_and_only_for_a_missing_file(tmp_path, monkeypatch, superpoint_weights):
    """The demo's ORB fallback keys on WeightsUnavailableError: offline / disabled yes; a named
    file that is missing or a checksum mismatch no."""
    monkeypatch.setenv(ENV_URL, f"http://127.0.0.1:{free_port()}/superpoint_v1.pth")
    with pytest.raises(WeightsUnavailableError) as e:
        resolve_weights(None)  # the env var's URL is used when none is given
    assert isinstance(e.value, WeightsDownloadError)
    assert "127.0.0.1" in str(e.value) and "--features orb" in str(e.value)
    with pytest.raises(WeightsUnavailableError):
        resolve_weights(None, allow_download=False)
    with pytest.raises(WeightsError) as e:
        resolve_weights(tmp_path / "named.pth")
    assert not isinstance(e.value, WeightsUnavailableError)
    with serve_directory(superpoint_weights.parent) as base:
        with pytest.raises(WeightsDownloadError) as e:
            resolve_weights(None, url=f"{base}/{superpoint_weights.name}", sha256="ab" * 32)
    assert not isinstance(e.value, WeightsUnavailableError)  # something came, and it was wrong


def test_weights_report_follows_the_resolution_order(tmp_path, monkeypatch, superpoint_weights):
    rep = weights_report()
    assert [c.state for c in rep.candidates] == ["not given", "not set", "missing", "enabled"]
    assert rep.used is None and rep.error is None
    monkeypatch.setenv(ENV_WEIGHTS, str(superpoint_weights))
    rep = weights_report()
    assert rep.used == superpoint_weights and rep.sha256 == sha(superpoint_weights) and not rep.official
    rep = weights_report(tmp_path / "gone.pth")  # a named file that is missing stops the search
    assert rep.used is None and "gone.pth" in rep.error
