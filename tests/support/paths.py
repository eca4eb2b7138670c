"""Where the checkout's folders are, for tests that run its tools, read its docs or start a process on it."""
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
