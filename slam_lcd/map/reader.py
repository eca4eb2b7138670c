"""Reading a map folder: the manifest and the files it lists, each checked before it is used.

Every file is checked against the size and sha256 the manifest gives, and arrays load with
``allow_pickle=False``: a truncated, tampered or foreign file is one :class:`MapError` naming it.
The folder's layout and how it is written: :mod:`slam_lcd.map.store`.
"""
from __future__ import annotations

import json
import os
from pathlib import Path
from typing import BinaryIO

import numpy as np

from ..files.hashing import sha256_of, sha256_of_file
from .contents import FORMAT_NAME, MANIFEST, MISSING, SCHEMA, MapError, MapGraph, MapManifest, SessionKeyframes


def is_map(path: str | Path) -> bool:
    return (Path(path) / MANIFEST).is_file()


def read_manifest(root: str | Path) -> MapManifest:
    """The manifest of the map at ``root`` (schema and shape checked; files not opened)."""
    root = Path(root)
    mpath = root / MANIFEST
    if not root.exists():
        raise MapError("no such map folder", root)
    if not mpath.is_file():
        raise MapError(f"not a slam-lcd map: no {MANIFEST} in the folder", root)
    try:
        data = json.loads(mpath.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise MapError(f"cannot be read as a map manifest ({e.__class__.__name__}: {e})", mpath) from None
    if not isinstance(data, dict) or data.get("format") != FORMAT_NAME:
        raise MapError("not a slam-lcd map manifest", mpath)
    schema = data.get("schema")
    if schema != SCHEMA:
        newer = isinstance(schema, int) and schema > SCHEMA
        raise MapError(f"map schema {schema!r}: this slam-lcd reads schema {SCHEMA} "
                       f"({'upgrade slam-lcd' if newer else 'rebuild the map from its logs'})", mpath)
    try:
        m = MapManifest(features=dict(data["features"]), sessions=list(data["sessions"]),
                        graph_file=data.get("graph_file"), vocab_file=data.get("vocab_file"),
                        files=dict(data["files"]),
                        created=str(data.get("created", "")), updated=str(data.get("updated", "")),
                        generation=int(data.get("generation", 0)))
        for s in m.sessions:
            for key in ("name", "file", "keyframes", "kf_id_start", "kf_id_end", "T_map_session", "component"):
                if key not in s:
                    raise KeyError(key)
    except (KeyError, TypeError, ValueError) as e:
        raise MapError(f"map manifest lacks or garbles {e}", mpath) from None
    return m


def _checked(root: Path, manifest: MapManifest, name: str, fh: BinaryIO | None = None) -> Path:
    """``root/name`` after its size and sha256 match the manifest's (``fh``: the file opened already)."""
    path = root / name
    meta = manifest.files.get(name)
    if meta is None:
        raise MapError(f"the manifest does not list {name}", root / MANIFEST)
    if fh is None and not path.is_file():
        raise MapError(MISSING, path)
    size = os.fstat(fh.fileno()).st_size if fh is not None else path.stat().st_size
    if size != int(meta.get("bytes", -1)):
        raise MapError(f"map file is {size} bytes, the manifest says {meta.get('bytes')} (truncated or replaced)",
                       path)
    if (sha256_of_file(fh) if fh is not None else sha256_of(path)) != meta.get("sha256"):
        raise MapError("map file's sha256 differs from the manifest's (modified after it was written)", path)
    return path


def open_listed(root: str | Path, manifest: MapManifest, name: str) -> BinaryIO:
    """Open a file the manifest lists, for reading later: a writer that replaces it meanwhile
    (and removes the old generation) cannot take it from under an open file."""
    path = Path(root) / name
    try:
        return open(path, "rb")
    except FileNotFoundError:
        raise MapError(MISSING, path) from None
    except OSError as e:
        raise MapError(f"cannot be opened ({e.strerror})", path) from None


def _load_arrays(path: Path, names: tuple[str, ...], fh: BinaryIO | None = None,
                 optional: tuple[str, ...] = ()) -> dict[str, np.ndarray]:
    try:
        with np.load(fh if fh is not None else path, allow_pickle=False) as z:
            missing = [n for n in names if n not in z.files]
            if missing:
                raise MapError(f"map file lacks arrays {missing}", path)
            return {n: z[n] for n in (*names, *(o for o in optional if o in z.files))}
    except MapError:
        raise
    except Exception as e:  # zip damage, pickled objects, bad CRC
        raise MapError(f"cannot be read as map arrays ({e.__class__.__name__}: {e})", path) from None


def read_session(root: str | Path, manifest: MapManifest, index: int) -> SessionKeyframes:
    root = Path(root)
    path = _checked(root, manifest, manifest.sessions[index]["file"])
    s = SessionKeyframes(**_load_arrays(path, SessionKeyframes.ARRAYS, optional=SessionKeyframes.OPTIONAL))
    s.check(path)
    return s


# arrays of a vocabulary snapshot (see slam_lcd.vocab.database.BowDatabase.snapshot)
VOCAB_ARRAYS = ("kf_ids", "desc_kind", "dim", "n_images", "centres_q", "centres_scale", "centres_f16", "lengths",
                "counts", "images", "bow_offsets", "bow_words", "bow_counts", "proj", "graph", "index_state",
                "image_ends")


def read_vocab(root: str | Path, manifest: MapManifest, fh: BinaryIO | None = None) -> dict[str, np.ndarray] | None:
    """The vocabulary snapshot's arrays (checked like every map file), or None when the map has none.

    ``fh``: the snapshot opened when the map was opened (:func:`open_listed`), so that a reader
    gets the generation its manifest names even after a writer has committed a newer one."""
    if manifest.vocab_file is None:
        return None
    root = Path(root)
    path = _checked(root, manifest, manifest.vocab_file, fh)
    return _load_arrays(path, VOCAB_ARRAYS, fh)


def read_graph(root: str | Path, manifest: MapManifest) -> MapGraph:
    if manifest.graph_file is None:
        return MapGraph.empty()
    root = Path(root)
    path = _checked(root, manifest, manifest.graph_file)
    g = MapGraph.from_file(_load_arrays(path, MapGraph.ARRAYS, optional=MapGraph.OPTIONAL))
    g.check(path)
    return g


# ----------------------------------------------------------------------------- writing
