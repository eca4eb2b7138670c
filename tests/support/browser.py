"""Screenshots of a web page that renders after it has loaded (a WebAssembly app such as Rerun's viewer).

``chromium --headless --screenshot`` shoots when the page has loaded, and its virtual time runs
ahead of the seconds a WebAssembly bundle takes to compile, so Rerun's web viewer is still at
"Loading Application Bundle" in the picture. Here the browser is driven over the DevTools protocol
instead (a minimal WebSocket client: the standard library has none) and shot in real time, again
and again, until the caller's test says the picture shows what it waits for.
"""
from __future__ import annotations

import base64
import json
import os
import shutil
import socket
import subprocess
import tempfile
import time
import urllib.request
from collections.abc import Callable
from contextlib import suppress


def find_browser() -> str | None:
    """A headless-capable Chromium on PATH (Debian's ``chromium`` first), or None."""
    return next((b for b in ("chromium", "chromium-browser", "google-chrome") if shutil.which(b)), None)


class _WebSocket:
    """Just enough of RFC 6455 for the DevTools protocol: masked text frames out, whole messages in."""

    def __init__(self, url: str):
        host_port, path = url.removeprefix("ws://").split("/", 1)
        host, port = host_port.split(":")
        self.sock = socket.create_connection((host, int(port)), timeout=30)
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall((f"GET /{path} HTTP/1.1\r\nHost: {host_port}\r\nUpgrade: websocket\r\n"
                           f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n")
                          .encode())
        head = b""
        while b"\r\n\r\n" not in head:
            head += self.sock.recv(1)
        if b" 101 " not in head.split(b"\r\n", 1)[0]:
            raise ConnectionError(f"no WebSocket upgrade: {head[:80]!r}")

    def send(self, text: str) -> None:
        data, mask = text.encode(), os.urandom(4)
        n = len(data)
        head = bytes([0x81]) + (bytes([0x80 | n]) if n < 126 else bytes([0x80 | 126]) + n.to_bytes(2, "big")
                                if n < 1 << 16 else bytes([0x80 | 127]) + n.to_bytes(8, "big"))
        self.sock.sendall(head + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(data)))

    def _exact(self, n: int) -> bytes:
        buf = b""
        while len(buf) < n:
            chunk = self.sock.recv(n - len(buf))
            if not chunk:
                raise ConnectionError("the browser closed the connection")
            buf += chunk
        return buf

    def recv(self) -> str:
        parts = []
        while True:
            b0, b1 = self._exact(2)
            n = b1 & 0x7F
            if n == 126:
                n = int.from_bytes(self._exact(2), "big")
            elif n == 127:
                n = int.from_bytes(self._exact(8), "big")
            parts.append(self._exact(n))
            if b0 & 0x80:  # the last fragment
                return b"".join(parts).decode()

    def close(self) -> None:
        with suppress(OSError):
            self.sock.close()


def screenshot_when(browser: str, url: str, port: int, ready: Callable[[bytes], bool], timeout_s: float = 90.0,
                    size: tuple[int, int] = (1200, 800)) -> bytes | None:
    """PNG bytes of ``url`` in headless ``browser`` once ``ready(png)`` holds (shot every 2 s), or the last
    one shot when ``timeout_s`` ran out; None when the browser could not be driven."""
    profile = tempfile.mkdtemp(prefix="slam-lcd-browser-")
    proc = subprocess.Popen([browser, "--headless=new", "--no-sandbox", "--use-angle=swiftshader",
                             "--enable-unsafe-swiftshader", f"--window-size={size[0]},{size[1]}",
                             f"--remote-debugging-port={port}", f"--user-data-dir={profile}", url],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    ws = None
    try:
        deadline = time.monotonic() + timeout_s
        pages: list = []
        while time.monotonic() < deadline and not pages:
            with suppress(OSError):
                listed = json.load(urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=5))
                pages = [p for p in listed if p.get("type") == "page"]
            time.sleep(0.5)
        if not pages:
            return None
        ws = _WebSocket(pages[0]["webSocketDebuggerUrl"])
        png, ident = None, 0
        while time.monotonic() < deadline:
            time.sleep(2.0)
            ident += 1
            ws.send(json.dumps({"id": ident, "method": "Page.captureScreenshot", "params": {"format": "png"}}))
            while True:
                answer = json.loads(ws.recv())
                if answer.get("id") == ident:
                    break
            png = base64.b64decode(answer.get("result", {}).get("data", ""))
            if png and ready(png):
                return png
        return png
    finally:
        if ws is not None:
            ws.close()
        proc.terminate()
        with suppress(subprocess.TimeoutExpired):
            proc.wait(timeout=20)
        shutil.rmtree(profile, ignore_errors=True)
