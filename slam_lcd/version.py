"""The package's version, a base module: what a report, a written log or ``--version`` stamps.

Why a module of its own and a constant: every layer stamps it (the report, the MCAP writer's
library line, the demo caches' keys, ``slam-lcd --version``), and importing it from the
package face would make each of them import upwards. Kept equal to ``pyproject.toml``'s
``version`` by a test; reading the installed metadata instead would cost every start-up and
give an editable install's stale number.
"""
from __future__ import annotations

__version__ = "0.1.0"
