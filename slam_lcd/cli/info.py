"""`slam-lcd info LOG`: format, duration, and per topic its type, count and rate (like `ros2 bag info`).

Rates come from a scan of the log's record times (no message is deserialised), so they
are real per-topic rates, not count / whole-log duration; ``--no-scan`` skips the scan.
"""
from __future__ import annotations

import sys
from datetime import UTC, datetime


def register(sub) -> None:
    p = sub.add_parser("info", help="list topics, types, counts, duration and rates of a log")
    p.add_argument("log", help="ROS1 .bag, rosbag2 directory, or .mcap file")
    p.add_argument("--no-scan", action="store_true",
                   help="do not scan message times: rates from counts / log duration "
                        "(default: scan, real per-topic rates)")
    p.set_defaults(func=run)


def _fmt_time(ns: int) -> str:
    dt = datetime.fromtimestamp(ns / 1e9, tz=UTC)
    return f"{dt:%Y-%m-%d %H:%M:%S.%f}"[:-3] + f" UTC ({ns // 1_000_000_000}.{ns % 1_000_000_000:09d})"


def _size(path) -> int:
    if path.is_dir():
        return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())
    return path.stat().st_size


def _human(n: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB"):
        if n < 1024 or unit == "GiB":
            return f"{n:.1f} {unit}" if unit != "B" else f"{int(n)} B"
        n /= 1024
    return f"{n:.1f} GiB"


def topic_rates(reader) -> dict[str, tuple[int, int, int]]:
    """topic -> (count, first log time, last log time) from a scan of the log's records."""
    seen: dict[str, list[int]] = {}
    for topic, _type, t, _raw in reader.raw_messages():
        s = seen.get(topic)
        if s is None:
            seen[topic] = [1, t, t]
        else:
            s[0] += 1
            s[2] = t
    return {k: (v[0], v[1], v[2]) for k, v in seen.items()}


def run(args) -> int:
    from ..io import open_log

    with open_log(args.log) as r:
        scanned = None if args.no_scan else topic_rates(r)
        out = sys.stdout
        print(f"Files:             {r.path}", file=out)
        truncated = "  [TRUNCATED: recovered part only]" if r.truncated else ""
        print(f"Format:            {r.format} ({r.storage})" + truncated, file=out)
        print(f"Bag size:          {_human(_size(r.path))}", file=out)
        n = r.message_count
        print(f"Duration:          {r.duration_ns / 1e9:.3f} s", file=out)
        if n:
            print(f"Start:             {_fmt_time(r.start_ns)}", file=out)
            print(f"End:               {_fmt_time(r.end_ns)}", file=out)
        print(f"Messages:          {n}", file=out)
        topics = sorted(r.topics.values(), key=lambda t: t.name)
        width = max([len(t.name) for t in topics] + [5])
        twidth = max([len(t.msgtype) for t in topics] + [4])
        print(f"Topic information: {len(topics)} topics", file=out)
        print(f"  {'topic':<{width}}  {'type':<{twidth}}  {'count':>8}  {'rate (Hz)':>10}", file=out)
        for t in topics:
            count = t.count
            if scanned is not None:
                c, first, last = scanned.get(t.name, (0, 0, 0))
                count = c
                rate = (c - 1) / ((last - first) / 1e9) if c > 1 and last > first else float("nan")
            else:
                rate = (count - 1) / (r.duration_ns / 1e9) if count > 1 and r.duration_ns > 0 else float("nan")
            rate_s = f"{rate:10.3f}" if rate == rate else f"{'-':>10}"
            print(f"  {t.name:<{width}}  {t.msgtype:<{twidth}}  {count:>8}  {rate_s}", file=out)
    return 0
