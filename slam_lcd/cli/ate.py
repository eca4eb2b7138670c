"""`slam-lcd ate REF EST`: absolute trajectory error of an estimate against a reference.

Same conventions as ``evo_ape``: ``-a`` aligns with SE(3), ``-a -s`` with Sim(3), ``-s``
alone corrects only the scale; ``--t_max_diff``/``--t_offset`` drive the time association.
Inputs are TUM / KITTI / EuRoC files or ``LOG:TOPIC``.
"""
from __future__ import annotations

import contextlib
import json
import math
from pathlib import Path

from ..atomic import write_text
from ..errors import InputError
from .util import check_output_path, write_guard
from ..io.trajectory_files import FORMATS


def register(sub) -> None:
    p = sub.add_parser(
        "ate",
        help="absolute trajectory error (and optional RPE) between two trajectories, evo-compatible",
        description="Absolute trajectory error of EST against REF (TUM / KITTI / EuRoC files or LOG:TOPIC).",
    )
    p.add_argument("ref", metavar="REF", help="reference trajectory: file or LOG:TOPIC")
    p.add_argument("est", metavar="EST", help="estimated trajectory: file or LOG:TOPIC")
    p.add_argument("-a", "--align", action="store_true", help="SE(3) Umeyama alignment (with -s: Sim(3))")
    p.add_argument("-s", "--correct_scale", action="store_true", help="correct the scale (with -a: Sim(3))")
    p.add_argument("--n_to_align", type=int, default=None, metavar="N", help="fit the alignment on the first N matched poses")
    p.add_argument("--t_max_diff", type=float, default=0.01, metavar="S", help="max stamp difference for association (s, default 0.01)")
    p.add_argument("--t_offset", type=float, default=0.0, metavar="S", help="offset added to EST stamps (s, default 0)")
    p.add_argument("--ref-format", choices=FORMATS, default=None, help="format of REF (default: detect)")
    p.add_argument("--est-format", choices=FORMATS, default=None, help="format of EST (default: detect)")
    p.add_argument("--ref-times", default=None, metavar="FILE", help="KITTI times file for REF")
    p.add_argument("--est-times", default=None, metavar="FILE", help="KITTI times file for EST")
    p.add_argument("--rpe", type=float, default=None, metavar="DELTA", help="also report RPE with this delta")
    p.add_argument("--rpe-unit", choices=("frames", "m"), default="m", help="unit of --rpe (default m)")
    p.add_argument("--plot", default=None, metavar="OUT.png", help="write a top view + error-over-time figure")
    p.add_argument("--json", default=None, metavar="OUT.json", help="write the results as JSON")
    p.set_defaults(func=run)


def _check_args(args) -> None:
    if not math.isfinite(args.t_max_diff) or args.t_max_diff < 0:
        raise InputError(f"--t_max_diff must be a finite number >= 0, got {args.t_max_diff}")
    if not math.isfinite(args.t_offset):
        raise InputError(f"--t_offset must be finite, got {args.t_offset}")
    if args.n_to_align is not None and args.n_to_align < 3:
        raise InputError(f"--n_to_align must be >= 3 (Umeyama needs 3 points), got {args.n_to_align}")
    if args.rpe is not None and (not math.isfinite(args.rpe) or args.rpe <= 0):
        raise InputError(f"--rpe must be > 0, got {args.rpe}")
    if args.n_to_align is not None and not (args.align or args.correct_scale):
        raise InputError("--n_to_align needs -a and/or -s")
    for out in (args.plot, args.json):
        check_output_path(out, args.ref, args.est, args.ref_times, args.est_times)
    if args.plot is not None and args.plot == args.json:
        raise InputError("--plot and --json name the same file", args.plot)


@contextlib.contextmanager
def _naming_both(args):
    """Association and alignment errors concern both trajectories: name both files."""
    from ..eval.errors import AlignmentError, AssociationError

    try:
        yield
    except (AssociationError, AlignmentError) as e:
        raise type(e)(f"reference {args.ref} and estimate {args.est}: {e.problem}") from None


def _short(spec: str) -> str:
    return Path(spec).name if Path(spec).exists() else str(spec)


def run(args) -> int:
    from ..eval import align_mode_from_flags, ate, rpe
    from ..eval.sources import load_trajectory_source

    _check_args(args)
    ref = load_trajectory_source(args.ref, args.ref_format, args.ref_times)
    est = load_trajectory_source(args.est, args.est_format, args.est_times)
    mode = align_mode_from_flags(args.align, args.correct_scale)
    with _naming_both(args):
        res = ate(ref, est, mode, t_max_diff=args.t_max_diff, t_offset=args.t_offset, n_to_align=args.n_to_align)
    tr, rot = res.translation, res.rotation
    print(f"reference: {args.ref} ({len(ref)} poses)")
    print(f"estimate:  {args.est} ({len(est)} poses)")
    print(
        f"matched:   {res.n_matched} pose pairs (t_max_diff {args.t_max_diff} s, t_offset {args.t_offset} s)"
    )
    align_text = res.alignment.label
    if mode in ("sim3", "scale"):
        align_text += f", scale {res.alignment.scale:.9g}"
    if res.alignment.n_used and res.alignment.n_used < res.n_matched:
        align_text += f", fitted on the first {res.alignment.n_used} pairs"
    print(f"alignment: {align_text}")
    print(
        f"ATE translation [m]: rmse {tr.rmse:.6f}  mean {tr.mean:.6f}  median {tr.median:.6f}  "
        f"std {tr.std:.6f}  min {tr.min:.6f}  max {tr.max:.6f}"
    )
    print(
        f"ATE rotation [deg]:  rmse {rot.rmse:.4f}  mean {rot.mean:.4f}  median {rot.median:.4f}  "
        f"std {rot.std:.4f}  min {rot.min:.4f}  max {rot.max:.4f}"
    )
    report = {"reference": str(args.ref), "estimate": str(args.est), "ate": res.to_dict()}
    if args.rpe is not None:
        with _naming_both(args):
            r = rpe(ref, est, args.rpe, args.rpe_unit, mode, t_max_diff=args.t_max_diff, t_offset=args.t_offset,
                    n_to_align=args.n_to_align)
        print(
            f"RPE ({args.rpe:g} {args.rpe_unit}, {len(r.errors)} pairs): translation rmse {r.translation.rmse:.6f} m, "
            f"rotation rmse {r.rotation.rmse:.4f} deg"
        )
        report["rpe"] = r.to_dict()
    if args.json:
        with write_guard(args.json):
            write_text(args.json, json.dumps(report, indent=2) + "\n")
        print(f"wrote {args.json}")
    if args.plot:
        from ..eval.plots import plot_ate

        with write_guard(args.plot):
            plot_ate(ref, res, est_name=_short(args.est), ref_name=_short(args.ref), out=args.plot)
        print(f"wrote {args.plot}")
    return 0
