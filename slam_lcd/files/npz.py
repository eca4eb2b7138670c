"""``.npz`` files whose small, regular arrays are deflated and whose large, dense ones are stored.

numpy writes an archive either all stored (``np.savez``) or all deflated
(``np.savez_compressed``). A map's files mix the two kinds: poses, covariances, ids, stamps and
loop records (4×4 float64 matrices with a constant last row, symmetric covariances, NaN ground
truth, repeated reason texts) deflate to a fraction, while quantised descriptors and vocabulary
centres hardly shrink and would only cost time to compress and inflate. Each member is written
in its own form; :func:`numpy.load` reads either. The members carry a fixed date, so the same
arrays give the same bytes (and the same sha256) every time.

Both writers here hold Ctrl-C and SIGTERM back until the archive is complete (milliseconds for a
map's session file: 6-26 ms for the demo's). An interrupt that lands inside :mod:`zipfile` while
it closes a member leaves the archive unable to close, and zipfile's own ValueError then replaces
the interrupt: the command would exit 1 with a traceback instead of 130. Held, the interrupt is
raised when the file is whole, and the caller's clean-up removes the file it was writing.
"""
from __future__ import annotations

import zipfile
from collections.abc import Collection, Mapping
from typing import Any, BinaryIO

import numpy as np

from ..runtime.interrupts import defer_sigint

FIXED_DATE = (1980, 1, 1, 0, 0, 0)
LEVEL = 6  # zlib's default: deflating a map's pose arrays at 9 saves under 2 % more, at twice the time


def write_npz(fh: BinaryIO, arrays: dict[str, np.ndarray], stored: Collection[str] = ()) -> None:
    """Write ``arrays`` to the open file ``fh`` as an ``.npz`` archive; the names in ``stored`` are not deflated."""
    with defer_sigint(), zipfile.ZipFile(fh, "w", allowZip64=True) as zf:
        for name, value in arrays.items():
            info = zipfile.ZipInfo(f"{name}.npy", date_time=FIXED_DATE)
            info.compress_type = zipfile.ZIP_STORED if name in stored else zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            with zf.open(info, "w", force_zip64=True) as member:
                np.lib.format.write_array(member, np.asanyarray(value), allow_pickle=False)


def save_npz(fh: BinaryIO, arrays: Mapping[str, Any]) -> None:
    """:func:`numpy.savez` (every member stored) with interrupts held back until the archive is whole.

    ``Any``: numpy's stub of savez has ``allow_pickle`` (numpy >= 2.1), a bool that ``**arrays`` could fill."""
    with defer_sigint():
        np.savez(fh, **arrays)
