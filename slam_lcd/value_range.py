"""The valid range of a numeric configuration key, declared beside the key's dataclass field.

A section's field reads ``jpeg_quality: int = ranged(90, "[0, 100]")``: the default, then the
range, kept in the field's metadata. :func:`slam_lcd.config.validate_config` reads every section's
ranges through :func:`numeric_ranges` and :func:`ordered_keys` and names the first key out of range
in a one-line error; a test checks that every int and float key has a range.

Notation: ``[a, b]`` closed, ``(a, b)`` open, ``inf`` unbounded; alternatives joined by ``or``
(``-1 or [1, inf)``). ``None`` is allowed exactly where the type says ``| None``. NaN is never in
range, and infinity only where a bound says ``inf]``. A key that must be below another key of its
section says so on the smaller one: ``ranged(0.1, "[0, inf)", below="max_depth_m")``.

A base module: every stage's ``config.py`` imports it, so it imports nothing of the package.
"""
from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterator
from typing import Any, TypeVar

ANY = "(-inf, inf)"

T = TypeVar("T")


def ranged(default: T, spec: str, *, below: str | None = None) -> T:
    """A dataclass field with ``default`` whose value must lie in ``spec`` (and below the key ``below``)."""
    metadata: dict[str, str] = {"range": spec}
    if below is not None:
        metadata["below"] = below
    return dataclasses.field(default=default, metadata=metadata)


def _fields(config: Any, prefix: str = "") -> Iterator[tuple[str, dataclasses.Field, Any]]:
    """``(key, field, holder)`` of every field of the dataclass instance ``config``, through its sections."""
    for f in dataclasses.fields(config):
        value = getattr(config, f.name)
        if dataclasses.is_dataclass(value) and not isinstance(value, type):
            yield from _fields(value, f"{prefix}{f.name}.")
        else:
            yield f"{prefix}{f.name}", f, config


def numeric_ranges(config: Any) -> dict[str, str]:
    """``"section.key"`` -> range spec of every ranged field of ``config`` (a dataclass instance), in field order."""
    return {key: f.metadata["range"] for key, f, _ in _fields(config) if "range" in f.metadata}


def ordered_keys(config: Any) -> list[tuple[str, str]]:
    """``(smaller, larger)`` keys of ``config``: the first must be below the second (``ranged(..., below=)``)."""
    pairs = []
    for key, f, holder in _fields(config):
        if "below" in f.metadata:
            larger = f.metadata["below"]
            if larger not in {g.name for g in dataclasses.fields(holder)}:
                raise ValueError(f"{key}: below={larger!r} names no key of its section")
            pairs.append((key, f"{key.rpartition('.')[0]}.{larger}".lstrip(".")))
    return pairs


def _alternatives(spec: str):
    out = []
    for part in spec.split(" or "):
        part = part.strip()
        if part[0] in "[(":
            lo, hi = (float(x) for x in part[1:-1].split(","))
            out.append((lo, hi, part[0] == "[", part[-1] == "]"))
        else:
            v = float(part)
            out.append((v, v, True, True))
    return out


def in_range(value, spec: str) -> bool:
    v = float(value)
    if math.isnan(v):
        return False
    for lo, hi, lo_in, hi_in in _alternatives(spec):
        if (v > lo or (lo_in and v == lo)) and (v < hi or (hi_in and v == hi)):
            return True
    return False


def describe(spec: str) -> str:
    return " or ".join(("in " + p.strip()) if p.strip()[0] in "[(" else p.strip() for p in spec.split(" or "))
