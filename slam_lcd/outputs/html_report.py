"""``report.html``: the run on one page, self-contained (no network, figures embedded).

What it shows is :func:`~.report.report_facts` (the same facts as ``report.json``) plus
the loop table of ``loops.csv``: summary, where the run came from (log, ground truth,
version, exact command line, ``--set`` overrides), the figures, ATE and RPE before and
after (translation and rotation, the alignment named), every loop candidate in a table
that sorts on a click (thumbnail, detector and back-end verdicts and reasons, error against
ground truth), the time per stage and the resolved config. Figures and thumbnails are
embedded as data URIs, so the file can be mailed on its own; the thumbnails link to the
full pictures in ``loops/`` beside it. A few lines of inline script sort the table; they
mark ``<body data-ready="1">`` when done and record script errors in ``data-errors`` (the
headless-browser test reads both).
"""
from __future__ import annotations

import base64
import html
from pathlib import Path

import cv2

from ..backend.pose_graph import ACCEPTED
from ..files.atomic import write_text
from ..map.summary import localisation_lines
from .loop_pictures import LOOPS_DIR, picture_name
from .map_cloud import TOP_FILE, TOP_ODOMETRY_FILE, cloud_lines
from .map_outputs import growth_png
from .report import command_text

THUMB_WIDTH = 240

_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;margin:1.5em auto;max-width:1400px;color:#222}
h1{font-size:1.5em}h2{font-size:1.2em;border-bottom:1px solid #ccc;padding-bottom:.2em;margin-top:1.6em}
table{border-collapse:collapse;font-size:.85em}td,th{border:1px solid #ddd;padding:.25em .5em;text-align:right}
th{background:#f3f3f3;cursor:pointer;position:sticky;top:0}td.t,th.t{text-align:left}
tr.accepted td{background:#eefaee}tr.backend_rejected td{background:#fdeeee}
img.fig{max-width:49%;border:1px solid #ddd}img.thumb{width:%(tw)dpx;display:block}
pre{background:#f7f7f7;padding:.8em;overflow:auto;font-size:.8em;max-height:30em}
code{background:#f3f3f3;padding:0 .2em}.ok{color:#1a7f1a}.bad{color:#b00020}
""".replace("%(tw)d", str(THUMB_WIDTH))

_JS = """
window.onerror=function(m){document.body.dataset.errors=(document.body.dataset.errors||'')+m+';'};
function sortBy(th){const t=th.closest('table'),b=t.tBodies[0],i=[...th.parentNode.children].indexOf(th);
 const asc=th.dataset.dir!=='asc';th.dataset.dir=asc?'asc':'desc';
 const key=r=>{const v=r.children[i].dataset.v;const n=parseFloat(v);return isNaN(n)?v:n};
 [...b.rows].sort((a,c)=>{const x=key(a),y=key(c);if(x===y)return 0;
  if(typeof x!==typeof y)return (typeof x==='number'?-1:1)*(asc?1:-1);return (x<y?-1:1)*(asc?1:-1)})
  .forEach(r=>b.appendChild(r))}
document.addEventListener('DOMContentLoaded',function(){
 document.querySelectorAll('table.sortable th').forEach(th=>th.addEventListener('click',()=>sortBy(th)));
 document.body.dataset.ready='1'});
"""


def _e(x) -> str:
    return html.escape(str(x), quote=True)


def data_uri(path: Path, max_width: int | None = None) -> str | None:
    """The image at ``path`` as a data URI (PNG as is; scaled to ``max_width`` as JPEG); None if unreadable."""
    if not path.is_file():
        return None
    if max_width is None:
        return "data:image/png;base64," + base64.b64encode(path.read_bytes()).decode()
    img = cv2.imread(str(path))
    if img is None:
        return None
    s = max_width / img.shape[1]
    img = cv2.resize(img, (max_width, max(1, round(img.shape[0] * s))), interpolation=cv2.INTER_AREA)
    ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, 80])
    return "data:image/jpeg;base64," + base64.b64encode(buf.tobytes()).decode() if ok else None


def _errors_table(ev: dict) -> list[str]:
    out = [f"<p>Alignment <b>{_e(ev['alignment'])}</b> (each trajectory its own, fitted on the associated poses); "
           f"association t_max_diff {ev['t_max_diff_s']} s, t_offset {ev['t_offset_s']} s; RPE pairs "
           f"{ev['rpe_delta']:g} {_e(ev['rpe_delta_unit'])} apart.</p>",
           "<table id='errors'><tr><th class=t>metric</th><th>odometry</th><th>corrected</th>"
           "<th>corrected / odometry</th></tr>"]
    for name, ba in (("ATE", ev["ate"]), ("RPE", ev["rpe"])):
        if ba is None:
            continue
        ratio = ba["ratio_after_before"]
        for part, unit, key in (("translation", "m", "translation_m"), ("rotation", "deg", "rotation_deg")):
            b, a = ba["before"][key], ba["after"][key]
            if b is None:  # position-only ground truth: no rotation error
                continue
            if part == "rotation":
                r = ""
            else:
                r = "odometry error ~0: no ratio" if ratio is None else f"{100 * ratio:.1f}%"
            if part == "rotation" and b["rmse"] >= 1e-6:
                r = f"{100 * a['rmse'] / b['rmse']:.1f}%"
            out.append(f"<tr><td class=t>{name} {part} RMSE ({unit})</td><td>{b['rmse']:.4f}</td>"
                       f"<td>{a['rmse']:.4f}</td><td>{r}</td></tr>")
            out.append(f"<tr><td class=t>{name} {part} max ({unit})</td><td>{b['max']:.4f}</td>"
                       f"<td>{a['max']:.4f}</td><td></td></tr>")
    out.append("</table>")
    if ev.get("not_measured"):
        out.append(f"<p>Position only (PointStamped ground truth): {_e(ev['not_measured'])}.</p>")
    return out


_LOOP_COLUMNS = [  # (header, loops.csv key or callable, text column)
    ("picture", None, True), ("query", "query_id", False), ("match", "match_id", False), ("BoW rank", "rank", False),
    ("BoW score", "bow_score", False), ("matches", "n_matches", False), ("graph nodes", "graph_nodes", False),
    ("pose inliers", "pose_inliers", False), ("detector", "verdict", True), ("detector reason", "reason", True),
    ("back end", "backend_verdict", True), ("back-end reason", "backend_reason", True),
    ("GT distance (m)", "gt_distance_m", False), ("error (m)", "err_trans_m", False),
    ("error (deg)", "err_rot_deg", False),
]


def _interest(r: dict, pictures: set[str]) -> int:
    """Table order before any click: accepted loops, back-end rejections, pictured candidates, the rest."""
    if r["backend_verdict"] == ACCEPTED:
        return 0
    if r["backend_verdict"]:
        return 1
    return 2 if picture_name(r["query_id"], r["match_id"], "rejected") in pictures else 3


def _loop_table(rows: list[dict], out_dir: Path, pictures: set[str], thumbs: dict | None = None) -> list[str]:
    rows = sorted(rows, key=lambda r: _interest(r, pictures))  # stable: the detector's order within a group
    head = "".join(f"<th class={'t' if txt else 'n'}>{_e(h)}</th>" for h, _, txt in _LOOP_COLUMNS)
    out = [f"<table id='loops' class='sortable'><thead><tr>{head}</tr></thead><tbody>"]
    for r in rows:
        verdict = ("accepted" if r["backend_verdict"] == ACCEPTED else
                   "backend_rejected" if r["backend_verdict"] else "")
        cells = []
        for _, key, txt in _LOOP_COLUMNS:
            if key is None:
                names = (picture_name(r["query_id"], r["match_id"], v) for v in ("accepted", "rejected"))
                name = next((n for n in names if n in pictures), None)
                if name and thumbs and name in thumbs:  # drawn this run: its thumbnail is at hand
                    uri: str | None = "data:image/jpeg;base64," + base64.b64encode(thumbs[name]).decode()
                else:
                    uri = data_uri(out_dir / LOOPS_DIR / name, THUMB_WIDTH) if name else None
                cells.append(f"<td class=t data-v='{0 if uri else 1}'>" + (
                    f"<a href='{LOOPS_DIR}/{_e(name)}'><img class=thumb src='{uri}' alt='{_e(name)}'></a>"
                    if uri else "") + "</td>")
                continue
            v = r.get(key, "")
            shown = f"{float(v):.3f}" if key in ("gt_distance_m", "err_trans_m", "err_rot_deg") and v != "" else v
            cells.append(f"<td class={'t' if txt else 'n'} data-v='{_e(v)}'>{_e(shown)}</td>")
        out.append(f"<tr class='{verdict}'>" + "".join(cells) + "</tr>")
    out.append("</tbody></table>")
    return out


def write_html_report(out_dir: Path, facts: dict, summary_lines: list[str], rows: list[dict],
                      figures: list[str], pictures: list[str], config_text: str, thumbs: dict | None = None) -> None:
    """``report.html`` in ``out_dir`` (see the module docstring); ``thumbs``: name -> JPEG thumbnail of the
    loop pictures drawn this run (others are read from ``loops/``)."""
    inp = facts["input"]
    loops = facts["loops"]
    body = ["<h1>slam-lcd run report</h1>",
            "<ul id='summary'>" + "".join(f"<li>{_e(s)}</li>" for s in summary_lines) + "</ul>",
            "<h2>Run</h2><table id='provenance'>"]
    for k, v in (("input log", inp["log"]), ("ground truth", inp["gt_source"] or "none"),
                 ("topics", ", ".join(f"{k}: {v}" for k, v in inp["topics"].items())),
                 ("slam-lcd", facts["slam_lcd_version"]), ("command line", command_text(facts["command_line"])),
                 ("--set overrides", " ".join(facts["config_overrides"]) or "none"),
                 ("interrupted", "yes: a partial result" if facts["interrupted"] else "no")):
        body.append(f"<tr><th class=t>{_e(k)}</th><td class=t><code>{_e(v)}</code></td></tr>")
    body.append("</table>")
    body += _map_section(facts.get("map"), facts.get("localization"))  # a map's result before the run's details
    if facts["eval"] is not None:
        body.append("<h2>Error against ground truth</h2>")
        body += _errors_table(facts["eval"])
    figs = [(f, data_uri(out_dir / f)) for f in figures]
    if any(u for _, u in figs):
        body.append("<h2>Figures</h2>")
        body += [f"<img class=fig src='{u}' alt='{_e(f)}'>" for f, u in figs if u]
    n_bad = loops["false_accepted"]
    body.append(f"<h2>Loops</h2><p>{loops['candidates']} candidates, {loops['verified']} verified by the detector, "
                f"<span class=ok>{loops['accepted']} accepted</span> and <span class=bad>"
                f"{loops['rejected_by_backend']} rejected</span> by the back end"
                + (f"; {n_bad} accepted loop(s) false by ground truth" if n_bad is not None else "")
                + ". Click a header to sort; a thumbnail opens its picture in <code>loops/</code>.</p>")
    body += _loop_table(rows, out_dir, set(pictures), thumbs)
    body += _cloud_section(facts.get("map_cloud"), out_dir)
    body.append("<h2>Time per stage</h2>"
                "<table id='stages'><tr><th class=t>stage</th><th>seconds</th><th>calls</th></tr>")
    body += [f"<tr><td class=t>{_e(k)}</td><td>{v['seconds']:.2f}</td><td>{v['calls']}</td></tr>"
             for k, v in facts["stages"].items()]
    body.append(f"</table><p>{facts['wall_s']:.1f} s wall for {facts['log_duration_s']:.1f} s of log.</p>")
    body.append(f"<h2>Resolved configuration</h2><pre id='config'>{_e(config_text)}</pre>")
    body.append("<h2>Outputs</h2><ul>" + "".join(f"<li><code>{_e(o)}</code></li>" for o in facts["outputs"]) + "</ul>")
    page = ("<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>"
            "<meta http-equiv='Content-Security-Policy' content=\"default-src 'none'; img-src data: 'self'; "
            "style-src 'unsafe-inline'; script-src 'unsafe-inline'\">"
            f"<title>slam-lcd report: {_e(Path(inp['log']).name)}</title><style>{_CSS}</style>"
            f"<script>{_JS}</script></head><body>" + "\n".join(body) + "</body></html>\n")
    write_text(out_dir / "report.html", page)


def _cloud_section(cloud: dict | None, out_dir: Path) -> list[str]:
    """The map seen from above with the odometry poses and with the corrected ones (same scale), and its figures."""
    if not cloud:
        return []
    if not cloud.get("built"):
        return [f"<h2>Map cloud</h2><p id='map-cloud'>{_e(cloud_lines(cloud)[0])}</p>"]
    out = ["<h2>Map cloud</h2><p>The keyframes' depth / stereo points merged in "
           f"{cloud['voxel_m']:g} m voxels, seen from above at the same scale: left with the odometry poses "
           "(<code>map_odometry.ply</code>), right with the corrected poses (<code>map.ply</code>). A wall seen twice "
           "is two lines before a good correction and one after.</p><div id='map-cloud'>"]
    for name, key in ((TOP_ODOMETRY_FILE, "odometry"), (TOP_FILE, "corrected")):
        uri = data_uri(out_dir / name)
        if uri:
            out.append(f"<img class=fig id='map-top-{key}' src='{uri}' alt='{_e(name)}'>")
    out.append("</div><ul>" + "".join(f"<li>{_e(line)}</li>" for line in cloud_lines(cloud)) + "</ul>")
    return out


def _growth_figure(summary: dict) -> list[str]:
    """The map's keyframes (all, kept) and size after each of its sessions (``map info --plot`` draws the same)."""
    import base64

    try:
        png = growth_png(summary)
    except Exception as e:  # a figure must never cost the user the report
        return [f"<p>map growth figure not drawn: {_e(e)}</p>"]
    if png is None:
        return []
    return [f"<img class=fig id='map-growth' src='data:image/png;base64,{base64.b64encode(png).decode()}' "
            "alt='map growth over sessions'>"]


def _map_section(summary: dict | None, localization: dict | None) -> list[str]:
    """The map this run appended to (sessions, ATE per session, loops between sessions) or was localised against."""
    out: list[str] = []
    if summary is not None and summary.get("sessions"):
        out.append(f"<h2>Map</h2><p><code>{_e(summary['root'])}</code>: {len(summary['sessions'])} sessions, "
                   f"{summary['n_keyframes']} keyframes, {summary['inter_session_accepted']} loops between sessions "
                   f"accepted of {len(summary['inter_session_loops'])} offered, {len(summary['components'])} "
                   "component(s).</p>")
        out.append("<table id='map_sessions'><tr><th class=t>session</th><th>keyframes</th><th>kept</th>"
                   "<th>component</th><th>loops to other sessions</th><th>ATE odometry (m)</th>"
                   "<th>ATE in the map (m)</th><th class=t>note</th></tr>")
        for r in summary["sessions"]:
            a, b = r.get("ate_odometry"), r.get("ate_map")
            out.append(f"<tr><td class=t>{_e(r['name'])}</td><td>{r['keyframes']}</td>"
                       f"<td>{r.get('kept_keyframes', r['keyframes'])}</td><td>{r['component']}</td>"
                       f"<td>{r['inter_session_loops']}</td><td>{'' if a is None else f'{a:.3f}'}</td>"
                       f"<td>{'' if b is None else f'{b:.4f}'}</td><td class=t>{_e(r.get('note', ''))}</td></tr>")
        out.append("</table>")
        out += _growth_figure(summary)
        loops = summary["inter_session_loops"]
        if loops:
            out.append("<table id='inter_session_loops'><tr><th>query</th><th class=t>session</th><th>match</th>"
                       "<th class=t>session</th><th class=t>verdict</th><th>GT distance (m)</th></tr>")
            for r in loops:
                d = r.get("gt_distance_m")
                verdict = "accepted" if r["accepted"] else r["reason"]
                out.append(f"<tr><td>{r['query_id']}</td><td class=t>{_e(r['query_session'])}</td>"
                           f"<td>{r['match_id']}</td><td class=t>{_e(r['match_session'])}</td>"
                           f"<td class=t>{_e(verdict)}</td><td>{'' if d is None else f'{d:.2f}'}</td></tr>")
            out.append("</table>")
    if localization is not None:
        out.append("<h2>Localisation against the map</h2><ul>"
                   + "".join(f"<li>{_e(line.strip())}</li>" for line in localisation_lines(localization)) + "</ul>")
    return out
