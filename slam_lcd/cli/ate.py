"""`slam-lcd ate REF EST`: absolute (or, with ``--rpe``, relative) pose error, with evo's flags and meanings.

Same flags as ``evo_ape`` / ``evo_rpe`` and the same numbers (tests compare both on real
trajectories): ``-r/--pose_relation``, ``-a`` (SE(3) Umeyama), ``-a -s`` (Sim(3)), ``-s``
alone (scale only), ``--n_to_align``, ``--align_origin``, ``--t_max_diff``/``--t_offset``
(time association), ``-p/--plot`` (show a window), ``--save_plot PATH``, ``--save_results
RES.zip`` (evo's archive: ``evo_res`` reads it); ``--rpe`` switches to evo_rpe with
``-d/--delta``, ``-u/--delta_unit`` (f, m, d, r), ``-t/--delta_tol``, ``--all_pairs`` and
``--pairs_from_reference`` (pairs are taken on the estimate unless that is given, as in evo).
Inputs are TUM / KITTI / EuRoC files or ``LOG:TOPIC``. ``--json`` writes every figure as JSON.
"""
from __future__ import annotations

import argparse
import contextlib
import json
import math
from pathlib import Path

from ..errors import InputError
from ..eval.relation_names import APE_RELATIONS, RPE_RELATIONS
from ..files.atomic import write_text
from ..io.trajectory_formats import FORMATS
from .util import check_outputs, write_guard

DELTA_UNIT_NAMES = {"f": "f", "frames": "f", "m": "m", "d": "d", "deg": "d", "r": "r", "rad": "r"}


def _delta_unit(text: str) -> str:
    try:
        return DELTA_UNIT_NAMES[text]
    except KeyError:
        raise argparse.ArgumentTypeError(f"invalid choice: {text!r} (choose from 'f', 'm', 'd', 'r')") from None


def register(sub) -> None:
    p = sub.add_parser(
        "ate",
        help="absolute (or with --rpe relative) pose error between two trajectories, with evo's flags",
        description="Absolute pose error of EST against REF (TUM / KITTI / EuRoC files or LOG:TOPIC), as "
                    "evo_ape computes it; with --rpe the relative pose error, as evo_rpe.",
    )
    p.add_argument("ref", metavar="REF", help="reference trajectory: file (format detected) or LOG:TOPIC")
    p.add_argument("est", metavar="EST", help="estimated trajectory: file (format detected) or LOG:TOPIC")
    algo = p.add_argument_group("algorithm options (evo's)")
    algo.add_argument("-r", "--pose_relation", default="trans_part", choices=RPE_RELATIONS, metavar="RELATION",
                      help=f"pose relation the error is measured on: {', '.join(RPE_RELATIONS)} "
                           "(default: trans_part, metres; point_distance_error_ratio only with --rpe)")
    align = algo.add_mutually_exclusive_group()
    align.add_argument("-a", "--align", action="store_true",
                       help="SE(3) Umeyama alignment, Sim(3) with -s (default: no alignment)")
    align.add_argument("--align_origin", action="store_true",
                       help="move the estimate's first pose onto the reference's (default: off)")
    algo.add_argument("-s", "--correct_scale", action="store_true",
                      help="correct the scale: with -a Sim(3), alone scale only (default: off)")
    algo.add_argument("--n_to_align", type=int, default=-1, metavar="N",
                      help="fit the Umeyama alignment on the first N matched poses (default: -1, all)")
    algo.add_argument("--t_max_diff", type=float, default=0.01, metavar="S",
                      help="max stamp difference for association, s (default: 0.01)")
    algo.add_argument("--t_offset", type=float, default=0.0, metavar="S",
                      help="offset added to EST stamps before association, s (default: 0)")
    rpe = p.add_argument_group("RPE options (evo_rpe's; need --rpe)")
    rpe.add_argument("--rpe", action="store_true",
                     help="relative pose error instead of absolute (default: absolute, evo_ape)")
    rpe.add_argument("-d", "--delta", type=float, default=None,
                     help="distance between the poses of a pair, in --delta_unit (default: 1)")
    rpe.add_argument("-u", "--delta_unit", type=_delta_unit, default=None, metavar="{f,m,d,r}",
                     help="unit of --delta: f frames, m metres travelled, d degrees, r radians of rotation "
                          "(default: f)")
    rpe.add_argument("-t", "--delta_tol", type=float, default=None,
                     help="relative tolerance of --delta in --all_pairs mode (default: 0.1)")
    rpe.add_argument("--all_pairs", action="store_true",
                     help="every pose pair --delta apart, not only consecutive ones (default: consecutive)")
    rpe.add_argument("--pairs_from_reference", action="store_true",
                     help="choose the pairs on the reference (default: on the aligned estimate, as evo)")
    p.add_argument("--rpe-unit", dest="delta_unit", type=_delta_unit, default=argparse.SUPPRESS,
                   help=argparse.SUPPRESS)  # old spelling of --delta_unit
    fmt = p.add_argument_group("input options")
    fmt.add_argument("--ref-format", choices=FORMATS, default=None, help="format of REF (default: detected)")
    fmt.add_argument("--est-format", choices=FORMATS, default=None, help="format of EST (default: detected)")
    fmt.add_argument("--ref-times", default=None, metavar="FILE",
                     help="KITTI times file for REF (default: none; KITTI poses are then matched by index)")
    fmt.add_argument("--est-times", default=None, metavar="FILE",
                     help="KITTI times file for EST (default: none; KITTI poses are then matched by index)")
    out = p.add_argument_group("output options")
    out.add_argument("-p", "--plot", action="store_true",
                     help="show the top view and error plot in a window (default: off; needs a display)")
    out.add_argument("--save_plot", default=None, metavar="PATH",
                     help="write the top view and error plot as PNG (default: none)")
    out.add_argument("--save_results", default=None, metavar="RES.zip",
                     help="write evo's result archive, readable by evo_res (default: none)")
    out.add_argument("--json", default=None, metavar="OUT.json",
                     help="write every figure as JSON (default: none)")
    p.set_defaults(func=run)


def _check_args(args) -> None:
    if not math.isfinite(args.t_max_diff) or args.t_max_diff < 0:
        raise InputError(f"--t_max_diff must be a finite number >= 0, got {args.t_max_diff}")
    if not math.isfinite(args.t_offset):
        raise InputError(f"--t_offset must be finite, got {args.t_offset}")
    if args.n_to_align != -1 and args.n_to_align < 3:
        raise InputError(f"--n_to_align must be >= 3 (Umeyama needs 3 points) or -1 (all), got {args.n_to_align}")
    if args.n_to_align != -1 and not (args.align or args.correct_scale):
        raise InputError("--n_to_align needs -a and/or -s")
    rpe_given = (("--delta", args.delta is not None), ("--delta_unit", args.delta_unit is not None),
                 ("--delta_tol", args.delta_tol is not None), ("--all_pairs", args.all_pairs),
                 ("--pairs_from_reference", args.pairs_from_reference))
    rpe_only = [name for name, given in rpe_given if given]
    if rpe_only and not args.rpe:
        raise InputError(f"{', '.join(rpe_only)} only apply to the relative pose error: add --rpe")
    if not args.rpe and args.pose_relation not in APE_RELATIONS:
        raise InputError(f"--pose_relation {args.pose_relation} only applies to the relative pose error: add --rpe")
    if args.rpe:
        args.delta = 1.0 if args.delta is None else args.delta
        args.delta_unit = args.delta_unit or "f"
        args.delta_tol = 0.1 if args.delta_tol is None else args.delta_tol
        if not math.isfinite(args.delta) or args.delta <= 0:
            raise InputError(f"--delta must be > 0, got {args.delta}")
        if args.delta_unit == "f" and not float(args.delta).is_integer():
            raise InputError(f"--delta in frames must be a whole number, got {args.delta}")
        if not math.isfinite(args.delta_tol) or args.delta_tol < 0:
            raise InputError(f"--delta_tol must be >= 0, got {args.delta_tol}")
    check_outputs({"--save_plot": args.save_plot, "--save_results": args.save_results, "--json": args.json},
                  {"REF": args.ref, "EST": args.est, "--ref-times": args.ref_times, "--est-times": args.est_times})


@contextlib.contextmanager
def _naming_both(args):
    """Association and alignment errors concern both trajectories: name both files."""
    from ..eval.errors import AlignmentError, AssociationError

    try:
        yield
    except (AssociationError, AlignmentError) as e:
        raise type(e)(f"reference {args.ref} and estimate {args.est}: {e.problem}") from None


def _short(spec: str) -> str:
    """A legend name: a file's stem, ``LOG:TOPIC`` as the log's stem and the topic (not full paths)."""
    if Path(spec).exists():
        return Path(spec).stem
    log, sep, topic = str(spec).rpartition(":")
    return f"{Path(log).stem}:{topic}" if sep and Path(log).exists() else str(spec)


def run(args) -> int:
    from ..eval.align import align_mode_from_flags
    from ..eval.relations import ape_by_relation, rpe_by_relation
    from ..sensors.trajectories import load_trajectory_source

    _check_args(args)
    # KITTI matrices as written (evo's reading), so the figures equal evo's to the last digits
    ref = load_trajectory_source(args.ref, args.ref_format, args.ref_times, file_rotations=True)
    est = load_trajectory_source(args.est, args.est_format, args.est_times, file_rotations=True)
    mode = align_mode_from_flags(args.align, args.correct_scale)
    common = dict(align_origin=args.align_origin, t_max_diff=args.t_max_diff, t_offset=args.t_offset,
                  n_to_align=None if args.n_to_align == -1 else args.n_to_align)
    with _naming_both(args):
        if args.rpe:
            res = rpe_by_relation(ref, est, args.pose_relation, args.delta, args.delta_unit, mode,
                                  all_pairs=args.all_pairs, pairs_from_reference=args.pairs_from_reference,
                                  rel_delta_tol=args.delta_tol, **common)
        else:
            res = ape_by_relation(ref, est, args.pose_relation, mode, **common)
    print(f"reference: {args.ref} ({len(ref)} poses)")
    print(f"estimate:  {args.est} ({len(est)} poses)")
    print(f"matched:   {res.n_matched} pose pairs (t_max_diff {args.t_max_diff} s, t_offset {args.t_offset} s)")
    align_text = res.alignment.label
    if res.alignment.mode in ("sim3", "scale") or (res.alignment.mode == "origin" and args.correct_scale):
        align_text += f", scale {res.alignment.scale:.9g}"
    if res.alignment.mode in ("se3", "sim3", "scale") and res.alignment.n_used < res.n_matched:
        align_text += f", fitted on the first {res.alignment.n_used} pairs"
    print(f"alignment: {align_text}")
    print(res.title())
    unit = f" [{res.unit}]" if res.unit else ""
    stats = res.stats
    print(f"  {len(res.errors)} errors{unit}: " + "  ".join(f"{k} {stats[k]:.6f}" for k in
                                                          ("rmse", "mean", "median", "std", "min", "max", "sse")))
    ref_name, est_name = _short(args.ref), _short(args.est)
    if args.json:
        report = {"reference": str(args.ref), "estimate": str(args.est), res.metric: res.to_dict()}
        with write_guard(args.json):
            write_text(args.json, json.dumps(report, indent=2) + "\n")
        print(f"wrote {args.json}")
    if args.save_results:
        from ..io.results_zip import write_evo_results

        with write_guard(args.save_results):
            write_evo_results(args.save_results, res, ref_name=ref_name, est_name=est_name)
        print(f"wrote {args.save_results}")
    if args.save_plot or args.plot:
        from ..eval.plots import plot_pose_error

        fig = plot_pose_error(ref, res, est_name=est_name, ref_name=ref_name)
        if args.save_plot:
            from ..eval.plots import save_figure

            with write_guard(args.save_plot):
                save_figure(fig, args.save_plot)
            print(f"wrote {args.save_plot}")
        if args.plot:
            _show(fig)
    return 0


def _show(fig) -> None:
    """evo's --plot: the figure in a window. Without a display or an interactive backend, say so and go on
    (the numbers are already printed; --save_plot writes the same figure)."""
    import os
    import sys

    import numpy as np
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    def note(why: str) -> None:
        print(f"note: --plot shows no window ({why}); use --save_plot PATH", file=sys.stderr)

    if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY") or sys.platform in ("darwin", "win32")):
        return note("no display")
    canvas = FigureCanvasAgg(fig)  # render the figure, then hand the pixels to an interactive window
    canvas.draw()
    pixels = np.asarray(canvas.buffer_rgba())
    import matplotlib.pyplot as plt

    for backend in ("QtAgg", "TkAgg", "GTK3Agg", "MacOSX"):
        try:
            plt.switch_backend(backend)
            break
        except Exception:  # backend not installed
            continue
    else:
        return note("no interactive matplotlib backend installed")
    plt.figure(figsize=fig.get_size_inches())
    plt.imshow(pixels)
    plt.axis("off")
    plt.tight_layout()
    plt.show()
