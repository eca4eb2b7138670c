"""Run configuration: typed dataclasses, YAML presets, ``--set section.key=value`` overrides.

Each stage owns its section (``slam_lcd/<stage>/config.py``; the batch driver's, which sits above the
stages, is kept here: :mod:`.batch_section`); this module composes them.
Unknown keys are errors, values are type-checked and range-checked (each key's range is
declared beside its field: ``ranged(default, "[0, 100]")``, :mod:`slam_lcd.value_range`), and
:func:`save_config` writes the resolved configuration next to a run's outputs.
"""
from __future__ import annotations

import dataclasses
import difflib
import types
import typing
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any, Literal

import yaml

from ..backend.config import BackendConfig
from ..cloud.config import MapCloudConfig
from ..errors import ConfigError, FileMissingError
from ..eval.config import EvalConfig
from ..features.config import FeaturesConfig
from ..files.atomic import write_text
from ..frontend.config import FrontendConfig
from ..io.config import IOConfig
from ..lcd.config import LcdConfig
from ..map.config import MapConfig
from ..sensors.config import SensorsConfig
from ..value_range import describe, in_range, numeric_ranges, ordered_keys, ranged
from ..vocab.config import VocabConfig
from .batch_section import BatchConfig

# presets are package data (slam_lcd/data/configs/*.yaml): found through importlib.resources,
# so they are there in a wheel install as in a source checkout
PRESET_PACKAGE = "slam_lcd.data"
PRESET_FOLDER = "configs"


def _preset_root():
    return resources.files(PRESET_PACKAGE) / PRESET_FOLDER


def preset_names() -> list[str]:
    """Names of the shipped presets (``default``, …), sorted."""
    root = _preset_root()
    return sorted(e.name[: -len(".yaml")] for e in root.iterdir() if e.name.endswith(".yaml"))


def preset_text(name: str) -> str:
    """The YAML text of the shipped preset ``name``; an unknown name is a ConfigError with near misses."""
    entry = _preset_root() / f"{name}.yaml"
    if not entry.is_file():
        names = preset_names()
        close = difflib.get_close_matches(name, names, n=3)
        hint = f"; did you mean {' or '.join(repr(c) for c in close)}?" if close else ""
        raise ConfigError(f"no preset named {name!r}{hint} (presets: {names})")
    return entry.read_text(encoding="utf-8")


@dataclass
class RunConfig:
    """Section `run`: what ``slam-lcd run`` writes (how it evaluates against ground truth: section `eval`)."""

    # a loop is counted false when its keyframes' ground-truth positions are further apart than this (m)
    loop_true_max_distance: float = ranged(3.0, "(0, inf)")
    # write trajectory.png and ate_over_time.png
    plots: bool = True
    # trajectory.png: a plane (xy, xz, yz), 3-D (xyz) or auto (the plane the motion spans)
    plot_mode: Literal["auto", "xy", "xz", "yz", "xyz"] = "auto"
    # write corrected.mcap (input topics + corrected trajectory)
    write_mcap: bool = True
    # copy image topics into corrected.mcap too (large; `run --copy-images`); false copies every non-image topic
    copy_images: bool = False
    # corrected.mcap frames (slam_lcd.outputs.corrected_log): the corrected map frame, and the
    # odometry and body frames ("" = the odometry topic's frame_id / child_frame_id)
    mcap_map_frame: str = "map"
    mcap_odom_frame: str = ""
    mcap_body_frame: str = ""
    # loops/: a picture per accepted (and back-end-rejected) loop and a contact sheet
    # (slam_lcd.outputs.loop_pictures; keyframe images and features are kept on disk meanwhile)
    loop_pictures: bool = True
    # ... plus this many detector-rejected candidates that came closest
    loop_pictures_rejected: int = ranged(8, "[0, inf)")
    # also take keyframes on image overlap (frontend.kf_min_overlap): needs features of EVERY
    # frame, not only of keyframes (about 5x the SuperPoint cost at 10 Hz); odometry
    # thresholds alone are the default
    keyframe_on_overlap: bool = False
    # keyframes whose features are extracted in a background thread while earlier keyframes
    # go through loop detection and the back end (SuperPoint releases the GIL); 0 = one at a
    # time. Loops of a keyframe are then reported up to this many keyframes later.
    extract_ahead: int = ranged(2, "[0, 64]")
    # with extract_ahead > 0: BLAS and faiss threads of the loop-detection thread while a
    # keyframe's features are being extracted in the background, so that the extraction keeps a
    # core (slam_lcd/runtime/thread_limits.py); 0 = the libraries' defaults
    lcd_threads: int = ranged(1, "[0, 64]")
    # with extract_ahead > 0: keyframes extracted side by side (SuperPoint on the CPU; one on a GPU).
    # 1: one keyframe at a time on all of torch's threads. N > 1: N at once, torch's threads shared
    # out between them (on 2 cores: one each, no barrier between the cores after every operator;
    # the 2-lap demo 45.5 s -> 41.5 s, same results). At most extract_ahead; 0 = torch's thread count
    extract_workers: int = ranged(2, "[0, 64]")
    # messages of the log read (decompressed, checked, deserialised) this many ahead in a thread
    # of its own once loop detection hardly waits for features (features cached, a GPU, many
    # cores), so that the reading overlaps it (slam_lcd/io/prefetch.py, runner._ReadAheadJudge);
    # 0 = always read in the main thread
    read_ahead: int = ranged(64, "[0, 4096]")


@dataclass
class Config:
    io: IOConfig = field(default_factory=IOConfig)
    sensors: SensorsConfig = field(default_factory=SensorsConfig)
    frontend: FrontendConfig = field(default_factory=FrontendConfig)
    features: FeaturesConfig = field(default_factory=FeaturesConfig)
    vocab: VocabConfig = field(default_factory=VocabConfig)
    lcd: LcdConfig = field(default_factory=LcdConfig)
    backend: BackendConfig = field(default_factory=BackendConfig)
    eval: EvalConfig = field(default_factory=EvalConfig)
    run: RunConfig = field(default_factory=RunConfig)
    batch: BatchConfig = field(default_factory=BatchConfig)
    map: MapConfig = field(default_factory=MapConfig)
    map_cloud: MapCloudConfig = field(default_factory=MapCloudConfig)


def _coerce(value: Any, tp: Any, where: str) -> Any:
    """Check/convert ``value`` to the annotated type ``tp`` (str from the CLI is parsed as YAML)."""
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        for a in args:
            if a is type(None):
                continue
            try:
                return _coerce(value, a, where)
            except ConfigError:
                pass
        raise ConfigError(f"{where}: value {value!r} does not fit {tp}")
    if typing.get_origin(tp) is typing.Literal:
        if value not in args:
            raise ConfigError(f"{where}: {value!r} is not one of {list(args)}")
        return value
    if dataclasses.is_dataclass(tp):
        if not isinstance(value, dict):
            raise ConfigError(f"{where}: expected a mapping, got {type(value).__name__}")
        return _from_dict(tp, value, where)
    if origin in (list, tuple):
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{where}: expected a list, got {value!r}")
        inner = args[0] if args else Any
        out = [_coerce(v, inner, f"{where}[{i}]") for i, v in enumerate(value)]
        return out if origin is list else tuple(out)
    if origin is dict:
        if not isinstance(value, dict):
            raise ConfigError(f"{where}: expected a mapping, got {value!r}")
        return dict(value)
    if tp is Any:
        return value
    if tp is bool:
        if isinstance(value, bool):
            return value
        raise ConfigError(f"{where}: expected true/false, got {value!r}")
    if tp is float:
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return float(value)
        raise ConfigError(f"{where}: expected a number, got {value!r}")
    if tp is int:
        if isinstance(value, int) and not isinstance(value, bool):
            return value
        raise ConfigError(f"{where}: expected an integer, got {value!r}")
    if tp is str:
        if isinstance(value, str):
            return value
        raise ConfigError(f"{where}: expected a string, got {value!r}")
    return value


def _from_dict(cls, data: dict, where: str = ""):
    hints = typing.get_type_hints(cls)
    names = {f.name for f in dataclasses.fields(cls)}
    odd = [k for k in data if not isinstance(k, str)]
    if odd:  # YAML reads `1:`, `true:`, `null:` as a number, a boolean, nothing: never a key of ours
        kind = {bool: "a boolean", int: "an integer", float: "a number", type(None): "null"}.get(
            type(odd[0]), f"a {type(odd[0]).__name__}")
        raise ConfigError(f"key {odd[0]!r} in section {where or 'top'} is not a name (YAML reads it as {kind}); "
                          f"keys are names such as {min(names)}")
    unknown = set(data) - names
    if unknown:
        moved = [f"{where}.{u} moved to {MOVED_KEYS[f'{where}.{u}']}" for u in sorted(unknown)
                 if f"{where}.{u}" in MOVED_KEYS]
        if moved:
            raise ConfigError(f"unknown key(s) {sorted(unknown)} in section {where}: {'; '.join(moved)}")
        guesses = [f"{u!r} -> {near[0]!r}" for u in sorted(unknown)
                   if (near := difflib.get_close_matches(u, names, n=1))]
        hint = f"; did you mean {', '.join(guesses)}?" if guesses else ""
        raise ConfigError(f"unknown key(s) {sorted(unknown)} in section {where or 'top'}{hint} "
                          f"(known: {sorted(names)})")
    kwargs = {k: _coerce(v, hints[k], f"{where}.{k}".lstrip(".")) for k, v in data.items()}
    return cls(**kwargs)


# keys that moved to another section: a config naming the old place gets an error that says where
MOVED_KEYS = {"run.align": "eval.align", "run.t_max_diff": "eval.t_max_diff", "vocab.top_k": "lcd.top_k",
              "vocab.exclude_recent_s": "lcd.exclude_recent_s", "vocab.exclude_recent_n": "lcd.exclude_recent_n"}


def config_to_dict(cfg) -> dict:
    return dataclasses.asdict(cfg)


def apply_override(cfg: Config, assignment: str) -> Config:
    """Apply one ``section.key=value`` override (value parsed as YAML) and re-validate."""
    if "=" not in assignment:
        raise ConfigError(f"override {assignment!r} must look like section.key=value")
    key, raw = assignment.split("=", 1)
    try:
        value = yaml.safe_load(raw) if raw.strip() else ""
    except yaml.YAMLError as e:
        raise ConfigError(f"override {assignment!r}: value is not valid YAML ({e.__class__.__name__})") from None
    data = config_to_dict(cfg)
    node = data
    parts = key.strip().split(".")
    for p in parts[:-1]:
        if not isinstance(node, dict) or p not in node:
            raise ConfigError(f"override {assignment!r}: unknown section {p!r}{_near_miss(data, key.strip())}")
        node = node[p]
    if not isinstance(node, dict) or parts[-1] not in node:
        raise ConfigError(f"override {assignment!r}: unknown key {key!r}{_near_miss(data, key.strip())}")
    node[parts[-1]] = value
    return _from_dict(Config, data)


def config_keys(data: dict | None = None) -> list[str]:
    """Every ``section.key`` of the configuration (what ``--set`` accepts)."""
    data = config_to_dict(Config()) if data is None else data
    keys: list[str] = []
    for section, values in data.items():
        keys += [f"{section}.{k}" for k in values] if isinstance(values, dict) else [section]
    return keys


def _near_miss(data: dict, key: str) -> str:
    """'; did you mean …?' for an unknown ``section.key``: close full keys, or the same key in another section."""
    keys = config_keys(data)
    close = difflib.get_close_matches(key, keys, n=3, cutoff=0.7)
    leaf = key.rsplit(".", 1)[-1]
    close += [k for k in keys if k.rsplit(".", 1)[-1] == leaf and k not in close]
    if not close:
        close = [k for k in keys if difflib.get_close_matches(leaf, [k.rsplit(".", 1)[-1]], n=1, cutoff=0.8)][:3]
    return f"; did you mean {' or '.join(close[:3])}?" if close else ""


def validate_config(cfg: Config, path: str | Path | None = None) -> Config:
    """Range-check every numeric key (the ranges beside the fields); one-line ConfigError naming the key."""
    data = config_to_dict(cfg)
    for key, spec in numeric_ranges(cfg).items():
        section, name = key.split(".", 1)
        value = data.get(section, {}).get(name)
        if value is None or isinstance(value, bool):
            continue
        if not in_range(value, spec):
            raise ConfigError(f"{key} = {value!r} is out of range: it must be {describe(spec)}", path)
    for small, large in ordered_keys(cfg):
        (s1, k1), (s2, k2) = small.split(".", 1), large.split(".", 1)
        if data[s1][k1] >= data[s2][k2]:
            raise ConfigError(f"{small} = {data[s1][k1]!r} must be below {large} = {data[s2][k2]!r}", path)
    if cfg.frontend.T_body_camera is not None:
        from ..geometry import pose_from_list

        try:
            pose_from_list(cfg.frontend.T_body_camera)
        except ConfigError as e:
            raise ConfigError(e.problem, path) from None
    return cfg


def load_config(source: str | Path | None = None, overrides: list[str] | tuple[str, ...] = ()) -> Config:
    """Load a preset name (``default``, ``orb`` …) or a YAML path, then apply overrides."""
    data: dict = {}
    if source is not None:
        path = Path(source)
        where: Path | None = path
        if not path.suffix and not path.exists():
            where = None
            text = preset_text(str(source))
        else:
            if not path.is_file():
                raise FileMissingError(f"configuration file not found (--config): give a YAML file or a preset name "
                                       f"({', '.join(preset_names())})", path)
            try:
                text = path.read_text(encoding="utf-8")
            except UnicodeDecodeError as e:
                raise ConfigError(f"not valid YAML ({e.__class__.__name__})", path) from None
        prefix = "" if where is not None else f"preset {source!r}: "
        try:
            data = yaml.safe_load(text) or {}
        except yaml.YAMLError as e:
            raise ConfigError(f"{prefix}not valid YAML ({e.__class__.__name__})", where) from None
        if not isinstance(data, dict):
            raise ConfigError(f"{prefix}top level of a config file must be a mapping", where)
        try:
            cfg = _from_dict(Config, data)
        except ConfigError as e:
            raise ConfigError(prefix + e.problem, where) from None
        if where is None:  # a preset: range errors name it
            try:
                validate_config(cfg)
            except ConfigError as e:
                raise ConfigError(prefix + e.problem) from None
        else:
            validate_config(cfg, where)
    else:
        cfg = Config()
    for ov in overrides:
        cfg = apply_override(cfg, ov)
    return validate_config(cfg)


def dump_config(cfg: Config) -> str:
    return yaml.safe_dump(config_to_dict(cfg), sort_keys=False)


def save_config(cfg: Config, path: str | Path) -> None:
    write_text(path, dump_config(cfg))
