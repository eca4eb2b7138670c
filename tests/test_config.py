import pytest
import yaml

from slam_lcd.config import Config, apply_override, load_config, save_config
from slam_lcd.errors import ConfigError


def test_default_roundtrip(tmp_path):
    cfg = load_config()
    out = tmp_path / "config.yaml"
    save_config(cfg, out)
    again = load_config(out)
    assert again == cfg


def test_override_and_unknown_key():
    cfg = apply_override(Config(), "io.stamp_source=log_time")
    assert cfg.io.stamp_source == "log_time"
    with pytest.raises(ConfigError, match="unknown key"):
        apply_override(Config(), "io.no_such_key=3")
    with pytest.raises(ConfigError):
        apply_override(Config(), "io.stamp_source=sideways")  # not a permitted value


def test_unknown_key_in_file(tmp_path):
    p = tmp_path / "bad.yaml"
    p.write_text(yaml.safe_dump({"io": {"bogus": 1}}))
    with pytest.raises(ConfigError, match="bogus"):
        load_config(p)


def test_presets_load():
    from slam_lcd.config import PRESET_DIR

    presets = sorted(PRESET_DIR.glob("*.yaml"))
    assert presets, "data/configs holds the presets"
    for p in presets:
        load_config(p.stem)
