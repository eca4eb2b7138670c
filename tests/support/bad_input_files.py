"""Builders of broken inputs for tests/cli/test_bad_input.py, and the checks every case makes.

Broken files are made in temporary folders from the real files under ``../shared/data``
and from short demo logs: a log rewritten with one message altered, an MCAP whose zstd
chunk is damaged or that carries a topic of an undefined type, a truncated JPEG, an
unreadable BMP, a pickled (not plain) weights file, trajectory files with repeated stamps
or non-unit quaternions. Nothing here writes outside the folder it is given.
"""
from __future__ import annotations

import contextlib
import hashlib
import logging
import os
import re
import shutil
import struct
import subprocess
import sys
from pathlib import Path

from support.paths import REPO

# ---------------------------------------------------------------------------- checks


def sha256_tree(*paths) -> dict[str, str]:
    """sha256 of every file under ``paths`` (a file or a folder), keyed by path."""
    out = {}
    for p in paths:
        p = Path(p)
        files = [p] if p.is_file() else sorted(f for f in p.rglob("*") if f.is_file()) if p.exists() else []
        for f in files:
            out[str(f)] = hashlib.sha256(f.read_bytes()).hexdigest()
    return out


# tqdm redraws, and the one line per stage printed when stderr is not a terminal (slam_lcd.runtime.progress)
_BAR = re.compile(r"\d+%\||\d+/\d+ \[|it/s|frame/s|img/s|: (?:done|\d+(?:/\d+)? \S+) in \d+\.\d s")


def message_lines(text: str) -> list[str]:
    """Lines a user reads: progress-bar redraws (carriage returns, tqdm bars) left out."""
    lines = []
    for raw in text.splitlines():
        line = raw.split("\r")[-1].strip()
        if line and not _BAR.search(line):
            lines.append(line)
    return lines


def assert_one_line(err: str, *needles: str) -> str:
    """stderr is exactly one line (besides progress bars), mentions every needle, no traceback."""
    assert "Traceback" not in err, err
    lines = message_lines(err)
    assert len(lines) == 1, lines
    for n in needles:
        assert n in lines[0], (n, lines[0])
    assert "\x1b[" not in lines[0], "ANSI escape codes in the message"
    return lines[0]


def leftovers(*folders) -> list[str]:
    """Temporary names slam-lcd writers use (staging folders, atomic temp files) under ``folders``."""
    found = []
    for d in folders:
        d = Path(d)
        if d.is_dir():
            found += [str(p) for p in d.rglob(".*")
                      if ".slam-lcd-" in p.name or re.match(r"^\..+\.[a-z0-9_]{6,}$", p.name)]
    return found


def assert_set_state(out: Path, state: str, names) -> None:
    """``out`` holds nothing ('absent'), a complete set ('complete') or a set marked partial ('partial')."""
    out = Path(out)
    assert not leftovers(out, out.parent), leftovers(out, out.parent)
    if state == "absent":
        assert not out.exists(), sorted(p.name for p in out.iterdir())
        return
    present = {p.name for p in out.iterdir()}
    if state == "complete":
        assert "PARTIAL.txt" not in present
        assert {"config.yaml", "report.json", "report.md"} <= present, present
    else:
        assert "PARTIAL.txt" in present, present
    assert present <= set(names) | {"PARTIAL.txt"} | {"notes.txt"}, present


def run_cli(argv, capfd) -> tuple[int, str, str]:
    """``slam-lcd ARGV`` in this process (so tests can inject faults); returns (status, stdout, stderr).

    stderr is captured at the file-descriptor level: what C libraries print is seen too.
    """
    from slam_lcd.cli.main import main

    root = logging.getLogger()
    for h in list(root.handlers):  # left by an earlier main() bound to an earlier test's stderr
        if type(h) is logging.StreamHandler:
            root.removeHandler(h)
    # main() calls logging.basicConfig, which does nothing while pytest's log capture handler is
    # installed: give the root logger the handler the command line would have
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("%(levelname)s: %(message)s"))
    root.addHandler(handler)
    capfd.readouterr()
    try:
        rc = main([str(a) for a in argv])
    finally:
        root.removeHandler(handler)
    out, err = capfd.readouterr()
    return rc, out, err


def run_subprocess(argv, cwd=None, extra_path=(), timeout=300) -> tuple[int, str, str]:
    """``python -m slam_lcd ARGV`` in a fresh process (start-up behaviour); ``extra_path`` goes first on sys.path."""
    env = dict(os.environ)
    old = [env["PYTHONPATH"]] if env.get("PYTHONPATH") else []
    env["PYTHONPATH"] = os.pathsep.join([*map(str, extra_path), str(REPO), *old])
    p = subprocess.run([sys.executable, "-m", "slam_lcd", *map(str, argv)], cwd=cwd, env=env,
                       capture_output=True, text=True, timeout=timeout)
    return p.returncode, p.stdout, p.stderr


# ---------------------------------------------------------------------------- logs


def rewrite_log(src: Path, dst: Path, edit) -> Path:
    """Copy log ``src`` to MCAP ``dst``, passing each message through ``edit(topic, index, msg)``.

    ``index`` counts messages per topic; ``edit`` returns the (possibly changed) message,
    or None to drop it. Messages are deserialised and serialised again by slam-lcd's own
    reader and writer.
    """
    from slam_lcd.io import open_log
    from slam_lcd.io.writers import open_writer

    counts: dict[str, int] = {}
    with open_log(src) as r, open_writer(dst, "mcap") as w:
        for m in r.messages():
            i = counts.get(m.topic, 0)
            counts[m.topic] = i + 1
            msg = edit(m.topic, i, m.msg)
            if msg is not None:
                w.write(m.topic, msg, m.log_time)
    return dst


def empty_log(dst: Path) -> Path:
    """An MCAP file that holds no message at all."""
    from slam_lcd.io.writers import open_writer

    with open_writer(dst, "mcap"):
        pass
    return dst


def _mcap_chunks(buf: bytes):
    """(record offset, compression, data offset, data length) of every Chunk record of an MCAP file."""
    off, out = 8, []
    while off + 9 <= len(buf):
        op = buf[off]
        (n,) = struct.unpack_from("<Q", buf, off + 1)
        if op == 0x02 and off > 8:  # footer
            break
        if op == 0x06:  # chunk: start, end, uncompressed size, crc, compression, records
            p = off + 9 + 8 + 8 + 8 + 4
            (sl,) = struct.unpack_from("<I", buf, p)
            comp = bytes(buf[p + 4:p + 4 + sl]).decode()
            p += 4 + sl
            (rl,) = struct.unpack_from("<Q", buf, p)
            out.append((off, comp, p + 8, rl))
        off += 9 + n
    return out


def damage_zstd_chunk(src: Path, dst: Path, which: int = 0) -> Path:
    """Copy of MCAP ``src`` whose first (``which``: that) zstd chunk no longer decompresses (frame header zeroed)."""
    buf = bytearray(Path(src).read_bytes())
    chunks = [c for c in _mcap_chunks(buf) if c[1] == "zstd"]
    assert chunks, "the source MCAP has no zstd chunk"
    _, _, data, _ = chunks[which]
    buf[data:data + 8] = bytes(8)
    Path(dst).write_bytes(bytes(buf))
    return dst


def add_undefined_topic(src: Path, dst: Path, topic: str = "/vendor/blob") -> Path:
    """Copy of MCAP ``src`` plus a topic whose schema is in an encoding no ROS tool can read."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    with open(src, "rb") as fi, open(dst, "wb") as fo:
        r = make_reader(fi)
        summary = r.get_summary()
        w = Writer(fo)
        w.start(profile="ros2", library="slam-lcd tests")
        schemas = {sid: w.register_schema(sc.name, sc.encoding, sc.data) for sid, sc in summary.schemas.items()}
        channels = {cid: w.register_channel(ch.topic, ch.message_encoding, schemas[ch.schema_id])
                    for cid, ch in summary.channels.items()}
        blob = w.register_channel(topic, "cdr", w.register_schema("vendor_msgs/msg/Blob", "vendor-binary", b"\x01\x02"))
        for n, (_sc, ch, m) in enumerate(r.iter_messages(log_time_order=True)):
            w.add_message(channels[ch.id], m.log_time, m.data, m.publish_time)
            if n % 25 == 0:
                w.add_message(blob, m.log_time, b"\x00\x01\x00\x00\x07\x00\x00\x00", m.log_time)
        w.finish()
    return dst


# ---------------------------------------------------------------------------- other files


def truncated_copy(src: Path, dst: Path, keep: float = 0.4) -> Path:
    data = Path(src).read_bytes()
    Path(dst).write_bytes(data[: int(len(data) * keep)])
    return dst


def pickled_weights(dst: Path) -> Path:
    """A torch file holding a Python object besides tensors (weights_only loading refuses it)."""
    import torch

    torch.save({"conv1a.weight": torch.zeros(1), "note": _Opaque()}, dst)
    return dst


class _Opaque:
    """Any class: its pickle is what torch's weights_only loader refuses."""


def tum_lines(path: Path) -> list[str]:
    return [line for line in Path(path).read_text().splitlines() if line.strip() and not line.startswith("#")]


# ---------------------------------------------------------------------------- mounts (root, Linux)


class Mounts:
    """tmpfs and read-only bind mounts for disk-full / read-only tests; all undone by :meth:`cleanup`."""

    def __init__(self):
        self.points: list[Path] = []

    @staticmethod
    def reason_unavailable() -> str | None:
        if not sys.platform.startswith("linux"):
            return "tmpfs and bind mounts are tested on Linux only"
        if os.geteuid() != 0:
            return "mounting a tmpfs / read-only bind mount needs root"
        if shutil.which("mount") is None:
            return "no mount command"
        return None

    def _mount(self, args, point: Path) -> None:
        p = subprocess.run(["mount", *args], capture_output=True, text=True)
        if p.returncode != 0:
            import pytest

            pytest.skip(f"cannot mount here ({p.stderr.strip() or p.returncode})")
        self.points.append(point)

    def tmpfs(self, point: Path, size: str) -> Path:
        point.mkdir(parents=True, exist_ok=True)
        self._mount(["-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(point)], point)
        return point

    def read_only(self, source: Path, point: Path) -> Path:
        point.mkdir(parents=True, exist_ok=True)
        self._mount(["--bind", str(source), str(point)], point)
        self._mount(["-o", "remount,ro,bind", str(point)], point)
        return point

    def cleanup(self) -> None:
        """Unmount every point; a file this process still holds open under one fails the test (a leak),
        and the point is then detached lazily so later tests are not left with a busy mount."""
        held = open_files_under(self.points)
        for point in reversed(self.points):
            with contextlib.suppress(Exception):
                if subprocess.run(["umount", str(point)], capture_output=True).returncode != 0:
                    subprocess.run(["umount", "-l", str(point)], capture_output=True)
        self.points.clear()
        assert not held, f"files left open after the command: {held}"


def open_files_under(folders) -> list[str]:
    """Paths this process holds open (file descriptors) inside any of ``folders``."""
    roots = [str(Path(f)) + os.sep for f in folders]
    found = []
    with contextlib.suppress(OSError):
        for fd in os.listdir("/proc/self/fd"):
            with contextlib.suppress(OSError):
                target = os.readlink(f"/proc/self/fd/{fd}")
                if any(target.startswith(r) for r in roots):
                    found.append(target)
    return found


def fill_disk(folder: Path, leave_bytes: int = 16 * 1024) -> None:
    """Fill the file system of ``folder`` until about ``leave_bytes`` are free."""
    st = os.statvfs(folder)
    free = st.f_bavail * st.f_frsize
    with open(folder / "filler.bin", "wb") as fh:
        with contextlib.suppress(OSError):
            fh.write(b"\0" * max(0, free - leave_bytes))
