"""``.npz`` files whose small, regular arrays are deflated and whose large, dense ones are stored.

numpy writes an archive either all stored (``np.savez``) or all deflated
(``np.savez_compressed``). A map's files mix the two kinds: poses, covariances, ids, stamps and
loop records (4×4 float64 matrices with a constant last row, symmetric covariances, NaN ground
truth, repeated reason texts) deflate to a fraction, while quantised descriptors and vocabulary
centres hardly shrink and would only cost time to compress and inflate. Each member is written
in its own form; :func:`numpy.load` reads either. The members carry a fixed date, so the same
arrays give the same bytes (and the same sha256) every time.
"""
from __future__ import annotations

import zipfile
from collections.abc import Collection
from typing import BinaryIO

import numpy as np

FIXED_DATE = (1980, 1, 1, 0, 0, 0)
LEVEL = 6  # zlib's default: deflating a map's pose arrays at 9 saves under 2 % more, at twice the time


def write_npz(fh: BinaryIO, arrays: dict[str, np.ndarray], stored: Collection[str] = ()) -> None:
    """Write ``arrays`` to the open file ``fh`` as an ``.npz`` archive; the names in ``stored`` are not deflated."""
    with zipfile.ZipFile(fh, "w", allowZip64=True) as zf:
        for name, value in arrays.items():
            info = zipfile.ZipInfo(f"{name}.npy", date_time=FIXED_DATE)
            info.compress_type = zipfile.ZIP_STORED if name in stored else zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            with zf.open(info, "w", force_zip64=True) as member:
                np.lib.format.write_array(member, np.asanyarray(value), allow_pickle=False)
