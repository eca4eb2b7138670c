"""What a GNC re-check changes: the loops it restores, the loops it removes, and their records.

Why a module of its own: :func:`~slam_lcd.backend.gnc.gnc_loop_weights` gives one weight per
candidate loop; turning weights into verdicts is a decision usable without a
:class:`~slam_lcd.backend.pose_graph.PoseGraph`, in two halves around the graph's iSAM2 update:
:func:`gnc_changes` decides before anything changes, and :func:`record_gnc_verdicts`, run
after the update (even an interrupted one), writes a verdict only where iSAM2 followed it,
so a record says 'accepted' exactly when its factor is in iSAM2.
"""
from __future__ import annotations

from .records import ACCEPTED, REJECTED, LoopEntry, LoopRecord


def gnc_changes(cands: list[LoopEntry], weights, residual_chi2, outlier_weight: float):
    """``(stats, add, remove)``: (loop, weight, residual chi2) per candidate, the rejected loops GNC
    calls inliers (weight at least ``outlier_weight``), the accepted loops it calls outliers."""
    stats, add, remove = [], [], []
    for lp, wi, chi2 in zip(cands, weights, residual_chi2, strict=True):
        stats.append((lp, float(wi), float(chi2)))
        inlier = wi >= outlier_weight
        if inlier and lp.record.verdict == REJECTED:
            add.append(lp)
        elif not inlier and lp.record.verdict == ACCEPTED:
            remove.append(lp)
    return stats, add, remove


def record_gnc_verdicts(stats, add: list[LoopEntry], remove: list[LoopEntry]) -> list[LoopRecord]:
    """Write every candidate's weight and residual, and the verdicts iSAM2 followed; the records that changed."""
    add_ids, remove_ids = {id(lp) for lp in add}, {id(lp) for lp in remove}
    changed = []
    for lp, wi, chi2 in stats:
        rec = lp.record
        rec.gnc_weight, rec.chi2_residual = wi, chi2
        if id(lp) in add_ids and lp.isam_index is not None:
            lp.set_verdict(ACCEPTED, "gnc", f"restored by GNC re-check (weight {wi:.2f}, residual chi2 {chi2:.1f})")
        elif id(lp) in remove_ids and lp.isam_index is None:
            lp.set_verdict(REJECTED, "gnc", f"GNC (TLS) outlier: weight {wi:.2f}, residual chi2 {chi2:.1f}")
        else:
            continue
        rec.history.append(f"{rec.verdict}: {rec.reason}")
        changed.append(rec)
    return changed
