"""`slam-lcd weights [fetch]`: where SuperPoint weights are looked for, which file is used, and fetching them.

``slam-lcd weights`` prints the resolver's search order (``--weights``,
``$SLAM_LCD_SUPERPOINT_WEIGHTS``, the cache, the download), the file a run would load, its
sha256 and whether it is the official Magic Leap release, and checks that it loads as
SuperPoint. Exit status 0 when a usable file is there, 1 when none is (a download would be
needed), 2 on an error. ``slam-lcd weights fetch`` downloads the official release (or
``--url``) into the cache, sha256-checked.
"""
from __future__ import annotations

from ..config import load_config
from ..features.config import SUPERPOINT_SHA256


def register(sub) -> None:
    p = sub.add_parser(
        "weights",
        help="show where SuperPoint weights are looked for and which file is used; 'fetch' downloads them",
        description="Show the SuperPoint weights search order, the file used, its sha256 and whether it is "
        "the official release (exit 1 when no file is available). 'slam-lcd weights fetch' downloads it.",
    )
    p.add_argument("action", nargs="?", choices=["show", "fetch"], default="show",
                   help="show (default): the search and the file used; fetch: download into the cache")
    p.add_argument("--weights", default=None, metavar="PATH",
                   help="check this weights file instead of searching (default: search as a run does)")
    p.add_argument("--url", default=None,
                   help="fetch: download from this URL (default: features.weights_url, else "
                        "$SLAM_LCD_SUPERPOINT_URL, else the official release)")
    p.add_argument("--force", action="store_true",
                   help="fetch: download again even if the cache already holds the file (default: keep it)")
    p.add_argument("--no-check", action="store_true",
                   help="show: do not load the file to check it is SuperPoint (default: check; needs torch)")
    p.add_argument("--config", default=None,
                   help="preset name or YAML file whose features.weights / cache_dir / weights_url are used "
                        "(default: 'default')")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="SECTION.KEY=VALUE",
                   help="override one configuration key (repeatable), "
                        "e.g. --set features.cache_dir=/data/cache (default: none)")
    p.set_defaults(func=run)


def run(args) -> int:
    cfg = load_config(args.config or "default", args.overrides)
    fc = cfg.features
    if args.action == "fetch":
        return _fetch(args, fc)
    return _show(args, fc)


def _show(args, fc) -> int:
    from ..features.weights import weights_report

    rep = weights_report(args.weights or fc.weights, cache=fc.cache_dir, url=fc.weights_url,
                         allow_download=fc.allow_download)
    print("SuperPoint weights are looked for in this order (first hit wins):")
    width = max(len(c.source) for c in rep.candidates)
    for k, c in enumerate(rep.candidates, 1):
        print(f"  {k}. {c.source:<{width}}  {c.location}  [{c.state}]")
    if rep.error:
        print(f"used:     none: {rep.error} (a named file is never skipped)")
        return 2
    if rep.used is None:
        print("used:     none found locally; a run would download the file above "
              "(`slam-lcd weights fetch`), and offline `slam-lcd demo` falls back to ORB features")
        return 1
    print(f"used:     {rep.used}")
    print(f"sha256:   {rep.sha256}")
    print("official: " + ("yes (the Magic Leap superpoint_v1.pth release)" if rep.official
                          else f"no (the official release has sha256 {SUPERPOINT_SHA256})"))
    if not args.no_check:
        from ..features.superpoint import SuperPoint
        from ..features.weights import load_state_dict_checked

        load_state_dict_checked(SuperPoint(), rep.used)  # a bad file is a one-line WeightsError, exit 2
        print("layout:   SuperPoint state dict, loads (strict)")
    return 0


def _fetch(args, fc) -> int:
    from ..features.weights import WEIGHTS_NAME, cache_dir, download_url, download_weights
    from ..files.hashing import sha256_of

    target = cache_dir(fc.cache_dir) / WEIGHTS_NAME
    if target.is_file() and not args.force:
        digest = sha256_of(target)
        print(f"already in the cache: {target} (sha256 {digest}"
              + (", the official release)" if digest == fc.weights_sha256 else ", not the official release)")
              + "; --force downloads it again")
        return 0
    url = download_url(args.url or fc.weights_url)
    print(f"downloading {url} -> {target}")
    download_weights(url, target, fc.weights_sha256)
    print(f"wrote {target} (sha256 {sha256_of(target)}, checked)")
    return 0
