"""Section `map`: how a multi-session map stores keyframes, joins sessions and localises a log."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from ..value_range import ranged


@dataclass
class MapConfig:
    """Section `map` (``slam-lcd run --map``, ``slam-lcd localize``; docs/multisession.md)."""

    # SuperPoint descriptors in the map: int4 (two values a byte and one scale per descriptor:
    # 132 B), int8 (260 B) or float16 (512 B); ORB's binary descriptors are stored as they are
    descriptor_form: Literal["int4", "int8", "float16"] = "int4"
    # link consecutive keyframes of a session by their visual relative pose (the loop chain run on
    # the pair: metric from the 3-D points) beside the odometry: the map's shape then rests on
    # unbiased visual steps, not on the odometry's scale and heading biases
    visual_links: bool = True
    # the online vocabulary's word centres in the map's snapshot (loaded instead of replaying every
    # keyframe's descriptors): int8 (one scale per word, 260 B a word) or float16 (512 B)
    vocab_centres: Literal["int8", "float16"] = "int8"
    # two sessions are joined only by this many pairwise-consistent loops between them (PCM):
    # one loop between two unconnected sessions cannot be checked against anything
    min_join_loops: int = ranged(3, "[1, inf)")
    # pairwise consistency of two loops between the same two sessions: chi-square quantile of
    # the cycle (loop, odometry in one session, loop back, odometry in the other), 6 dof
    pcm_probability: float = ranged(0.99, "(0, 1)")
    # odometry uncertainty per square-root metre travelled (variance grows with the distance, and with the
    # angle turned), used for the cycle's covariance, the link test and the joint solve where the session's
    # odometry gave no covariance or the front end modelled it (m/sqrt(m), rad/sqrt(m), rad/sqrt(rad), 1 sigma;
    # the front end's motion model has the same figures: docs/multisession.md)
    pcm_sigma_trans_per_m: float = ranged(0.05, "[0, inf)")
    pcm_sigma_rot_per_m: float = ranged(0.02, "[0, inf)")
    pcm_sigma_rot_per_rad: float = ranged(0.05, "[0, inf)")
    # the exact search for the largest consistent set stops after this many search nodes and takes
    # the largest set found so far (logged and recorded in the pair's decision)
    pcm_clique_budget: int = ranged(100000, "[1, inf)")
    # the joining set's keyframes must lie at least this far apart in each of the two sessions (m):
    # a look-alike place seen from a few consecutive keyframes gives loops that agree with each other
    min_join_span_m: float = ranged(2.0, "[0, inf)")
    # ... or their viewing directions at least this far apart in each session (deg; the angle of the rotation
    # between two keyframes' orientations; over 180: by distance alone). 60: twice the angle within which the
    # lifelong map counts two views as one place (place_angle_deg); two views 60 deg apart share a seventh of the
    # demo camera's 70 deg field of view. Keyframes are made every 15 deg turned (frontend.kf_min_rotation_deg),
    # so the 3 loops of a look-alike seen from a few consecutive keyframes span 30 deg or less
    min_join_view_angle_deg: float = ranged(60.0, "[0, inf)")
    # not joined ("ambiguous") when a second consistent set, disjoint from the largest, could join
    # on its own and holds at least this share of the largest set's loops
    join_ambiguity_ratio: float = ranged(0.5, "(0, inf)")
    # a visual link must agree with the odometry step it spans: chi-square quantile, 6 dof
    link_probability: float = ranged(0.999, "(0, 1)")
    # localise: a keyframe's pose from the map must agree with the poses of the localised
    # keyframes around it carried by odometry (translation m, rotation deg); the rest are outliers
    localize_max_disagreement_m: float = ranged(1.0, "(0, inf)")
    localize_max_disagreement_deg: float = ranged(15.0, "(0, 180]")
    # localise: a fix is confirmed only by a fix to another place, their map keyframes this far apart
    # or the log this far along between them (m): neighbouring keyframes that see one look-alike
    # place agree with each other too, so a look-alike must span more than this to confirm itself.
    # 3 m: wider than the demo world's repeated door-and-posters groups (2.2 m); the share localised
    # was the same from 0 to 4 m on the measured demo runs and fell at 5-6 m (the confirming window
    # of 10 keyframes is about 5 m)
    localize_min_place_separation_m: float = ranged(3.0, "[0, inf)")
    # localise: ... or their map keyframes look in directions at least this far apart (deg; the angle of the
    # rotation between the two map keyframes' orientations; over 180: by distance alone): views of two walls
    # are two places even a step apart, so a log turning in place or walking a small room confirms its fixes.
    # 60: as map.min_join_view_angle_deg; at 15 deg a keyframe (frontend.kf_min_rotation_deg) it is 4 keyframes
    # of a turn, well inside the 10-keyframe window that may confirm a fix
    localize_min_view_angle_deg: float = ranged(60.0, "[0, inf)")
    # localise: fixes falling into groups that disagree (a look-alike place and the true one): a group
    # wins only with at least this many times its rival's fixes; otherwise both are ambiguous. 2: a
    # look-alike corridor seen by 7 fixes against its true place's 16 was decided right at 1.5 and 2,
    # refused at 3
    localize_min_group_ratio: float = ranged(2.0, "[1, inf)")
    # wait for a writer's lock this long before refusing (seconds; 0: refuse at once)
    lock_timeout_s: float = ranged(60.0, "[0, inf)")
    # keep places and appearance variants, not every keyframe (slam_lcd.map.places): a keyframe that
    # a kept one of its place matches well keeps only its pose; false: every keyframe keeps everything
    lifelong: bool = True
    # a kept keyframe is of the same place when its camera lies within this distance (m) and its
    # optical axis within this angle (deg)
    place_radius_m: float = ranged(1.0, "(0, inf)")
    place_angle_deg: float = ranged(30.0, "(0, 180]")
    # the nearest kept keyframes of the place a new one is compared with
    place_compare: int = ranged(3, "[1, inf)")
    # redundant when at least this share of the new keyframe's descriptors are mutual nearest
    # neighbours of a kept keyframe of its place; when only that share of the kept one's are, the new
    # one is richer and takes its place; below it both ways, a new appearance of the place
    redundant_match_ratio: float = ranged(0.3, "(0, 1]")
    # a session is judged in the kept appearance its keyframes match best (median best ratio); when
    # even that is under this share of how well they match each other (median of consecutive
    # keyframes) it founds a new appearance (night in a map of days); a keyframe is redundant only
    # against kept keyframes of its own appearance; 0: every session is judged in a known one
    appearance_share: float = ranged(0.8, "[0, 1]")
    # kept keyframes (appearance variants) of one place at most; a new one beyond that evicts the
    # variant matched longest ago, first of its own appearance, then of one the place holds twice
    max_variants: int = ranged(4, "[1, inf)")
    # a lifelong map folds its dropped keyframes out of the joint graph (slam_lcd.map.fold) once every
    # loop touching them was made this many appends ago (a later contradiction can still judge a recent
    # pair's loops again); 0: never fold, the graph keeps a variable per keyframe of every visit
    fold_after_appends: int = ranged(3, "[0, inf)")
