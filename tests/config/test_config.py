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
    from slam_lcd.config import preset_names

    names = preset_names()
    assert "default" in names, "slam_lcd/data/configs holds the presets"
    for name in names:
        load_config(name)


def test_unknown_preset_suggests_near_misses():
    with pytest.raises(ConfigError, match=r"no preset named 'defualt'; did you mean 'default'"):
        load_config("defualt")


@pytest.mark.parametrize("assignment, hint", [
    ("backend.loop_kernl=huber", "did you mean backend.loop_kernel"),
    ("bakend.loop_kernel=huber", "did you mean backend.loop_kernel"),
    ("lcd.tree=dp", "did you mean vocab.tree"),  # the key lives in another section
])
def test_unknown_override_suggests_near_misses(assignment, hint):
    with pytest.raises(ConfigError, match=hint):
        apply_override(Config(), assignment)


def test_unknown_key_in_file_suggests(tmp_path):
    p = tmp_path / "typo.yaml"
    p.write_text(yaml.safe_dump({"lcd": {"top_kk": 3}}))
    with pytest.raises(ConfigError, match="did you mean 'top_kk' -> 'top_k'"):
        load_config(p)


@pytest.mark.parametrize("old,new", [("run.align", "eval.align"), ("vocab.top_k", "lcd.top_k"),
                                     ("vocab.exclude_recent_n", "lcd.exclude_recent_n")])
def test_a_key_that_moved_says_where_it_lives_now(tmp_path, old, new):
    """Every knob has one home: a config naming the old place gets a one-line error naming the new one."""
    section, key = old.split(".")
    p = tmp_path / "c.yaml"
    p.write_text(yaml.safe_dump({section: {key: 3}}))
    with pytest.raises(ConfigError, match=f"{old} moved to {new}"):
        load_config(str(p))
