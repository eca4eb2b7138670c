"""report.html: self-contained (no network, every image embedded), the facts of
report.json, one table row per loop candidate with thumbnails; rendered by headless
Chromium, it loads without script errors and shows the loop table."""
from __future__ import annotations

import csv
import json
import re
import subprocess

import pytest

from slam_lcd.outputs.loop_pictures import LOOPS_DIR

from support.browser import find_browser


def test_report_html_is_self_contained_and_complete(report_run):
    _, out, log = report_run
    page = (out / "report.html").read_text(encoding="utf-8")
    rep = json.loads((out / "report.json").read_text())
    srcs = re.findall(r"""\bsrc=['"]([^'"]*)['"]""", page)
    assert srcs and all(s.startswith("data:image/") for s in srcs)  # figures and thumbnails embedded
    hrefs = re.findall(r"""\bhref=['"]([^'"]*)['"]""", page)
    assert all(h.startswith(f"{LOOPS_DIR}/") and (out / h).is_file() for h in hrefs)  # pictures beside it
    assert not re.search(r"""(src|href)=['"]?(https?:)?//""", page)
    for fact in (str(log), rep["input"]["gt_source"], "slam-lcd run", "se3", "ATE rotation RMSE", "RPE translation",
                 "loop_detection", "t_max_diff"):
        assert fact in page, fact
    n_rows = len(list(csv.DictReader(open(out / "loops.csv"))))
    table = page[page.index("<table id='loops'"):]
    table = table[:table.index("</table>")]
    assert table.count("<tr class=") == n_rows
    assert table.count("<tr class='accepted'>") == rep["loops"]["accepted"]
    assert table.count("class=thumb") >= rep["loops"]["accepted"]
    assert "features:" in page and "kind: orb" in page  # the resolved config


def test_report_html_renders_in_headless_chromium(report_run, tmp_path):
    browser = find_browser()
    if browser is None:
        pytest.skip("no headless browser: install Debian's chromium package (apt-get install chromium) to run this")
    _, out, _ = report_run
    rep = json.loads((out / "report.json").read_text())
    args = [browser, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run", "--disable-extensions",
            f"--user-data-dir={tmp_path / 'profile'}", "--virtual-time-budget=5000"]
    url = (out / "report.html").resolve().as_uri()
    dom = subprocess.run([*args, "--dump-dom", url], capture_output=True, text=True, timeout=180)
    assert dom.returncode == 0, dom.stderr[-2000:]
    body = re.search(r"<body[^>]*>", dom.stdout).group(0)
    assert 'data-ready="1"' in body and "data-errors" not in body, body  # the script ran, without an error
    table = dom.stdout[dom.stdout.index('<table id="loops"'):]
    assert table[:table.index("</table>")].count('<tr class="accepted">') == rep["loops"]["accepted"]
    shot = tmp_path / "report.png"
    r = subprocess.run([*args, f"--screenshot={shot}", "--window-size=1400,2400", url], capture_output=True,
                       text=True, timeout=180)
    assert r.returncode == 0 and shot.stat().st_size > 50_000, r.stderr[-2000:]
