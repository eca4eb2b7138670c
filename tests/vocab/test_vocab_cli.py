"""`slam-lcd vocab train|info` on real corridor frames: from an image folder and from an MCAP log."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from slam_lcd.cli.main import main
from slam_lcd.vocab import Vocabulary


@pytest.fixture(scope="module")
def corridor_dir(shared_data):
    root = shared_data / "rtabmap_corridor"
    if not (root / "1.jpg").is_file():
        pytest.skip("corridor frames not found")
    return root


def test_train_from_folder_then_info(corridor_dir, tmp_path, capsys):
    out = tmp_path / "orb_dp.npz"
    rc = main(["vocab", "train", str(corridor_dir), "--out", str(out), "--features", "orb", "--max-images", "10"])
    assert rc == 0 and out.is_file()
    vocab = Vocabulary.load(out)
    assert vocab.meta["tree"] == "dp" and vocab.meta["features"] == "orb" and vocab.n_images == 10
    assert len(vocab) > 500 and vocab.desc_kind == "binary"
    assert f"{len(vocab)} words" in capsys.readouterr().out
    assert main(["vocab", "info", str(out)]) == 0
    text = capsys.readouterr().out
    assert f"{len(vocab)} words" in text and "level 0: 1 node(s)" in text
    # the baseline tree through the same command, with config overrides
    out2 = tmp_path / "orb_hk.npz"
    rc = main(["vocab", "train", str(corridor_dir), "--out", str(out2), "--features", "orb", "--tree", "hkmeans",
               "--max-images", "10", "--set", "vocab.hk_branching=6", "--set", "vocab.hk_depth=3"])
    assert rc == 0
    hk = Vocabulary.load(out2)
    assert hk.meta["tree"] == "hkmeans" and hk.depth == 3 and len(hk) <= 6**3


def test_train_from_mcap_log(corridor_dir, tmp_path):
    from slam_lcd.io.message_builders import image_msg
    from slam_lcd.io.writers import open_writer

    log = tmp_path / "frames.mcap"
    with open_writer(log, "mcap") as w:
        for i in range(1, 9):
            # the grey the folder reader gives (colour decode, then RGB -> grey, as eval-lcd reads folders)
            img = cv2.cvtColor(cv2.imread(str(corridor_dir / f"{i}.jpg"), cv2.IMREAD_COLOR), cv2.COLOR_BGR2GRAY)
            stamp = i * 10**8
            w.write("/camera/image_raw", image_msg(img, stamp, "camera"), stamp)
    out = tmp_path / "from_log.npz"
    assert main(["vocab", "train", str(log), "--image-topic", "/camera/image_raw", "--out", str(out),
                 "--features", "orb"]) == 0
    vocab = Vocabulary.load(out)
    assert vocab.n_images == 8
    # same frames from the folder give the same words
    out_dir = tmp_path / "from_dir.npz"
    assert main(["vocab", "train", str(corridor_dir), "--out", str(out_dir), "--features", "orb",
                 "--max-images", "8"]) == 0
    other = Vocabulary.load(out_dir)
    assert len(other) == len(vocab)
    x = np.concatenate([other.tree.words[:50]])
    assert np.array_equal(vocab.tree.quantize(x), other.tree.quantize(x))


def test_errors_are_one_line(tmp_path, capsys, corridor_dir):
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"PK\x03\x04 truncated")
    assert main(["vocab", "info", str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "bad.npz" in err and "Traceback" not in err
    assert main(["vocab", "info", str(tmp_path / "missing.npz")]) == 2
    assert "not found" in capsys.readouterr().err
    assert main(["vocab", "train", str(tmp_path / "nothing"), "--out", str(tmp_path / "v.npz")]) == 2
    assert main(["vocab", "train", str(corridor_dir / "1.jpg"), "--out", str(tmp_path / "v.npz"),
                 "--features", "orb"]) == 2
    assert "--image-topic" in capsys.readouterr().err
