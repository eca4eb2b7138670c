"""Places and appearance variants: which keyframes a map keeps as the same place is recorded day after day.

A map that stores every keyframe of every log grows with the days, not with the place. After
the joint solve of an append (when every new keyframe has its pose in the map frame), each new
keyframe is judged against the keyframes the map keeps, in order:

- **new place**: no kept keyframe of its component lies within ``map.place_radius_m`` and
  ``map.place_angle_deg`` (camera poses): it is kept and founds a place;
- **redundant**: one of the (up to ``map.place_compare``) nearest kept keyframes matches it well:
  at least ``map.redundant_match_ratio`` of *its* descriptors are mutual nearest neighbours of the
  kept one's within the matching distance (:func:`match_ratio`). It keeps its pose (every session
  stays in the map frame at full rate) but not its descriptors, keypoints, points or bag of words;
  the keyframe it matched is marked used now. Only when that kept keyframe would localise it: its 3-D
  points give this view a pose through the loop chain's pose stage (:mod:`slam_lcd.map.place_geometry`);
  otherwise it is kept as a variant (``Verdicts.reason`` says why);
- **richer**: not redundant, but that share of a near kept keyframe's descriptors lies in it: the
  same appearance, seen better (the kept one a blurred or dim moment). It takes the kept one's
  place, appearance and use (now); the kept one keeps only its pose. Why replace and not add a
  variant: both show one appearance, and the poor one would take a variant's room that another
  appearance may need; why not drop the new one: a later visit would find its matches in the poor
  view only. Only when it would localise the kept one (the same pose check, the other way round);
  otherwise it is kept as a variant;
- **new appearance** (a variant): kept keyframes are near but none matches it well either way
  (:func:`alike_ratio`; other lighting, moved objects): it is kept as another variant of the
  nearest kept keyframe's place. A place holds at most ``map.max_variants`` variants; a new one
  beyond that evicts the variant that has gone longest without being matched (by a later
  append's keyframe or loop), so what the map's users still meet stays: first among the new
  one's appearance, then among appearances the place holds twice, so that each appearance keeps
  its view of the place (:func:`_evicted`): a place keeps a view of every appearance seen there,
  as long as ``map.max_variants`` allows.

``map compact`` of a map that keeps places already applies the same rules to the kept views and
their records (:func:`prune`): a smaller ``map.max_variants``, or poses that later appends moved
together, take effect, and what stays keeps its place, appearance and last use.

Each kept keyframe has an **appearance** (sessions that look alike share one: the days, the
nights). A session is judged in the kept appearance it matches best as a whole (the median of its
keyframes' best ratios with the kept keyframes of that appearance near them, :func:`familiarity`),
or founds a new one when even that median is under ``map.appearance_share`` of the median ratio
between its own consecutive keyframes (night in a map of days). Its keyframes are redundant only
against kept keyframes of its appearance, never against another's (which a view a little off their
pose would not match), so each place a session passes gets a variant in its appearance, which the
next session in that appearance then matches.

Why mutual nearest neighbours of the stored descriptors first: the question is whether the map
would recognise this view from what it keeps, and the share of mutual matches between two views
of one place falls with the change of appearance (the table in docs/multisession.md gives the
measured figures). Why the pose check after it: a share does not say the matches agree with one
pose; night descriptors are less distinctive, and a night view a metre off its place's night view
shares a third of its descriptors with it yet gets no pose from it. The check runs only for the
pair the share rule picked; where either view has no 3-D points (a monocular map) the share rule
decides alone.
"""
from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from .place_geometry import Localises, View

NEW_PLACE, VARIANT, REDUNDANT, RICHER = "place", "variant", "redundant", "richer"
MATCH_COS = 0.75  # float descriptors (unit rows): mutual nearest neighbours at least this cosine apart
MATCH_HAMMING = 64  # binary descriptors (ORB, 256 bits): at most this many bits apart


def mutual_pairs(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows of ``a`` and of ``b`` that are each other's nearest neighbour within the matching distance."""
    if len(a) == 0 or len(b) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    if a.dtype == np.uint8:  # binary: Hamming distances from the bits
        A, B = np.unpackbits(a, axis=1).astype(np.float32), np.unpackbits(b, axis=1).astype(np.float32)
        dist = A @ (1 - B).T + (1 - A) @ B.T
        fwd, back = dist.argmin(1), dist.argmin(0)
        good = dist[np.arange(len(a)), fwd] <= MATCH_HAMMING
    else:
        sim = np.asarray(a, np.float32) @ np.asarray(b, np.float32).T
        fwd, back = sim.argmax(1), sim.argmax(0)
        good = sim[np.arange(len(a)), fwd] >= MATCH_COS
    rows = np.flatnonzero((back[fwd] == np.arange(len(a))) & good)
    return rows, fwd[rows]


def mutual_matches(a: np.ndarray, b: np.ndarray) -> int:
    """How many descriptors of ``a`` and ``b`` are each other's nearest neighbour (:func:`mutual_pairs`)."""
    return len(mutual_pairs(a, b)[0])


def match_ratio(a: np.ndarray, b: np.ndarray) -> float:
    """Share of ``a``'s descriptors (the view judged) that are mutual nearest neighbours of ``b``'s.

    Why of the view judged and not of the smaller set: a redundant view loses its descriptors, so the
    question is how much of *it* the kept view still holds. Counted against the smaller set, a kept
    view of 60 descriptors (a blurred or dim moment) holds "all" of an 800-descriptor view of the
    unchanged place, which then drops, and a later visit finds its matches in 60 descriptors."""
    return mutual_matches(a, b) / len(a) if len(a) and len(b) else 0.0


def alike_ratio(a: np.ndarray, b: np.ndarray) -> float:
    """How alike two views look: the larger of the two :func:`match_ratio` (of the poorer view's descriptors).

    Under ``map.redundant_match_ratio`` a new view is neither redundant nor richer: a new appearance."""
    return mutual_matches(a, b) / min(len(a), len(b)) if len(a) and len(b) else 0.0


@dataclass
class Kept:
    """A keyframe the map keeps: its camera pose in its component's frame, place, and when it was last matched."""

    kf_id: int
    T_map_camera: np.ndarray
    component: int
    place: int
    last_used: int
    descriptors: Callable[[], np.ndarray]
    appearance: int = 0
    # keypoints, 3-D points and camera (:mod:`slam_lcd.map.place_geometry`), read only when a pair is checked;
    # None: no geometry (the share rule decides alone)
    view: Callable[[], View | None] | None = None


@dataclass
class Verdicts:
    """What :func:`judge` decided for the new keyframes, and what it changed among the kept ones."""

    status: dict[int, str] = field(default_factory=dict)  # new kf id -> place / variant / redundant / richer
    place: dict[int, int] = field(default_factory=dict)  # kept kf id (new or old) -> place id
    matched: dict[int, int] = field(default_factory=dict)  # redundant new kf id -> the kept kf it matched
    replaced: dict[int, int] = field(default_factory=dict)  # richer new kf id -> the poorer kept kf it replaced
    used: set[int] = field(default_factory=set)  # kept kf ids matched now (their last_used becomes now)
    evicted: list[int] = field(default_factory=list)  # kept kf ids no longer kept (a full place's oldest variant)
    # (a replaced or evicted keyframe of the same append: status redundant, and out of ``place``)
    reason: dict[int, str] = field(default_factory=dict)  # new kf id -> why it is a variant the share rule dropped
    appearance: int = 0  # the appearance the session was judged in
    new_appearance: bool = False  # one the map did not hold (map.appearance_share)


New = tuple[int, np.ndarray, Callable[[], np.ndarray]]  # kf id, camera pose in the map frame, descriptors


class Ratios:
    """Mutual matches of keyframe pairs, each pair matched once, from descriptors each decoded once
    (a map stores them quantised; :func:`familiarity` and :func:`judge` meet the same keyframes)."""

    def __init__(self) -> None:
        self._mutual: dict[tuple[int, int], int] = {}
        self._decoded: dict[int, np.ndarray] = {}

    def shares(self, a: int, desc_a: Callable[[], np.ndarray], b: int,
               desc_b: Callable[[], np.ndarray]) -> tuple[float, float]:
        """(:func:`match_ratio` of ``a`` against ``b``, of ``b`` against ``a``): one count of mutual matches."""
        da, db = self._of(a, desc_a), self._of(b, desc_b)
        if not len(da) or not len(db):
            return 0.0, 0.0
        key = (a, b) if a <= b else (b, a)
        if key not in self._mutual:  # the same pairs either way: matched in one order
            self._mutual[key] = mutual_matches(da, db) if a <= b else mutual_matches(db, da)
        return self._mutual[key] / len(da), self._mutual[key] / len(db)

    def alike(self, a: int, desc_a: Callable[[], np.ndarray], b: int, desc_b: Callable[[], np.ndarray]) -> float:
        """:func:`alike_ratio` of the two views: the share of the poorer one's descriptors found in the other.

        Why the poorer one's here (and not in :func:`judge`'s redundancy): whether two views show one
        appearance does not depend on how many descriptors each found; a dim view of the day is still
        the day, and only the descriptors it has can say so."""
        return max(self.shares(a, desc_a, b, desc_b))

    def decoded(self, kf_id: int, desc: Callable[[], np.ndarray]) -> np.ndarray:
        """A keyframe's descriptors, decoded once."""
        return self._of(kf_id, desc)

    def _of(self, kf_id: int, desc: Callable[[], np.ndarray]) -> np.ndarray:
        if kf_id not in self._decoded:
            self._decoded[kf_id] = desc()
        return self._decoded[kf_id]


def familiarity(new: list[New], component: int, kept: list[Kept], conf,
                ratios: Ratios) -> tuple[dict[int, float], float | None]:
    """How well the map as it is knows a session's appearance: for each appearance of the kept
    keyframes, the median over the session's keyframes that have kept keyframes of that appearance
    near of their best :meth:`Ratios.alike` with those; and the median ratio of the session's
    keyframes with the one before them where that lies within the place's reach (None: no two do).

    Why a session's median and not each keyframe alone: at nearly the same pose another appearance
    still shares half its descriptors with a kept view (night against day: 0.49), while a view of
    that appearance a little off the pose shares a sixth (0.17); a keyframe alone looks redundant,
    the session as a whole does not. Why against the session's own consecutive keyframes: what a
    good match is depends on the descriptors (SuperPoint's revisits share about 0.65, ORB's about
    0.35), and the session's own views of one place in one appearance measure it."""
    cos_max = np.cos(np.radians(conf.place_angle_deg))
    compare = max(1, int(conf.place_compare))
    best: dict[int, list[float]] = {}
    own = []
    for j, (kf_id, T, desc) in enumerate(new):
        near = _near(T, component, kept, conf.place_radius_m, cos_max)
        for a in {k.appearance for k in near}:
            alike = [k for k in near if k.appearance == a][:compare]
            best.setdefault(a, []).append(max(ratios.alike(kf_id, desc, k.kf_id, k.descriptors) for k in alike))
        if j:
            prev_id, P, prev_desc = new[j - 1]
            if np.linalg.norm(P[:3, 3] - T[:3, 3]) <= conf.place_radius_m and P[:3, 2] @ T[:3, 2] >= cos_max:
                own.append(ratios.alike(kf_id, desc, prev_id, prev_desc))
    return {a: float(np.median(v)) for a, v in best.items()}, (float(np.median(own)) if own else None)


def appearance_of(known: dict[int, float], own: float | None, kept: list[Kept], conf) -> tuple[int, bool]:
    """The appearance a session is judged in, and whether it is a new one: the kept appearance it
    matches best, unless even that one's median is under ``map.appearance_share`` of its own."""
    if not known:  # nothing kept near (another area): the appearance the map holds most of
        looks = Counter(k.appearance for k in kept)
        return (max(looks, key=lambda a: (looks[a], -a)) if looks else 0), False
    a = max(known, key=lambda k: (known[k], -k))
    if own is None or known[a] >= conf.appearance_share * own:
        return a, False
    return max(k.appearance for k in kept) + 1, True


def judge(new: list[New], component: int, kept: list[Kept], conf, now: int, next_place: int,
          appearance: int = 0, ratios: Ratios | None = None, views: dict[int, Callable[[], View | None]] | None = None,
          localises: Localises | None = None) -> Verdicts:
    """Judge the new keyframes ``(kf id, camera pose in the map frame, descriptors)`` in order (module docstring).

    ``kept``: the map's kept keyframes (changed in place: new kept keyframes are added, replaced and
    evicted ones removed); ``now``: the append's generation (what ``last_used`` records);
    ``next_place``: the first free place id; ``appearance``: the appearance the session is judged in
    (:func:`appearance_of`): its keyframes are redundant only against kept keyframes of it; ``views``:
    the new keyframes' keypoints and 3-D points, ``localises``: the pose check with the ``lcd`` settings
    (:mod:`slam_lcd.map.place_geometry`; default ones when not given).
    """
    out = Verdicts(appearance=appearance)
    ratios, check = ratios or Ratios(), localises or Localises()
    for kf_id, T, desc in new:
        v = Kept(kf_id, T, component, -1, now, desc, appearance, (views or {}).get(kf_id))
        next_place = _place_view(v, kept, conf, ratios, check, out, next_place)
    return out


def prune(views: list[Kept], conf, ratios: Ratios | None = None, localises: Localises | None = None) -> Verdicts:
    """Views a map keeps already, with their records (place, appearance, last use), less what the rules
    drop now: each, in the order they were added, judged as :func:`judge` judges a new keyframe against
    the ones before it that stay, in its own appearance (``views`` changed in place).

    Why not :func:`judge` again: the kept views of a map lie too far apart for a session's own ratio
    (:func:`familiarity`), so every session would fall into one appearance, and their uses would be
    those of the judging, not of the appends that recorded them. A view that stays keeps its place,
    appearance and last use; one that a view before it holds (or that a richer view before it replaces)
    hands its last use on to that view, so the place's record of use stays."""
    out = Verdicts()
    ratios, check = ratios or Ratios(), localises or Localises()
    kept: list[Kept] = []
    for v in views:
        _place_view(v, kept, conf, ratios, check, out, -1)
    views[:] = kept
    return out


def _place_view(v: Kept, kept: list[Kept], conf, ratios: Ratios, check: Localises, out: Verdicts,
                next_place: int) -> int:
    """Judge one view against ``kept`` (changed in place), record the verdict in ``out``; the next free place id.

    A view with a place (``v.place >= 0``, :func:`prune`) keeps it when it stays as a new place or variant;
    one without (:func:`judge`) gets a new place, or the nearest kept view's. Redundant or richer only when
    the view that stays localises the one that goes (:func:`_unlocalised`); otherwise a variant."""
    near = _near(v.T_map_camera, v.component, kept, conf.place_radius_m, np.cos(np.radians(conf.place_angle_deg)))
    if not near:
        if v.place < 0:
            v.place, next_place = next_place, next_place + 1
        _keep(v, kept, NEW_PLACE, conf, out)
        return next_place
    alike = [k for k in near if k.appearance == v.appearance][:max(1, int(conf.place_compare))]
    shares = [ratios.shares(v.kf_id, v.descriptors, k.kf_id, k.descriptors) for k in alike]
    of_new, of_kept = [s[0] for s in shares], [s[1] for s in shares]
    why = ""
    if of_new and max(of_new) >= conf.redundant_match_ratio:  # the kept view holds this one
        match = alike[int(np.argmax(of_new))]
        why = _unlocalised(match, v, ratios, check)
        if not why:
            match.last_used = max(match.last_used, v.last_used)
            out.status[v.kf_id], out.matched[v.kf_id] = REDUNDANT, match.kf_id
            out.used.add(match.kf_id)
            return next_place
    elif of_kept and max(of_kept) >= conf.redundant_match_ratio:  # this view holds the kept one, and more
        poor = alike[int(np.argmax(of_kept))]
        why = _unlocalised(v, poor, ratios, check)
        if not why:
            v.place, v.last_used = poor.place, max(poor.last_used, v.last_used)
            kept[kept.index(poor)] = v
            out.status[v.kf_id], out.place[v.kf_id], out.replaced[v.kf_id] = RICHER, v.place, poor.kf_id
            out.matched.update({q: v.kf_id for q, m in out.matched.items() if m == poor.kf_id})
            _dropped(poor, out)
            return next_place
    if v.place < 0:
        v.place = near[0].place
    if why:
        out.reason[v.kf_id] = why
    _keep(v, kept, VARIANT, conf, out)
    return next_place


def _unlocalised(stays: Kept, goes: Kept, ratios: Ratios, check: Localises) -> str:
    """Why view ``stays`` would not localise view ``goes`` (the loop chain's pose stage on their mutual
    matches, :mod:`slam_lcd.map.place_geometry`); '' when it would, or when either has no 3-D points.

    Why: ``goes`` keeps only its pose, and a log passing there is localised by ``stays`` alone. A share of
    look-alike descriptors (a night view a metre off) gives matches but no pose; only a pose says the kept
    view serves that spot. Run for the one pair the share rule picked: a pose costs more than a share."""
    c = check.check(stays.kf_id, stays.view, goes.kf_id, goes.view,
                    lambda: mutual_pairs(ratios.decoded(goes.kf_id, goes.descriptors),
                                         ratios.decoded(stays.kf_id, stays.descriptors)))
    if c is None or c.ok:
        return ""
    return (f"view {stays.kf_id} would not localise view {goes.kf_id}: {c.reason} "
            f"({c.inliers} PnP inliers of {c.matches} mutual matches)")


def _keep(v: Kept, kept: list[Kept], status: str, conf, out: Verdicts) -> None:
    """``v`` kept as a new place or a variant; a place holding more than ``map.max_variants`` gives one up."""
    kept.append(v)
    out.status[v.kf_id], out.place[v.kf_id] = status, v.place
    variants = [k for k in kept if k.place == v.place]
    if len(variants) > conf.max_variants:
        old = _evicted(variants, v.kf_id, v.appearance, v.last_used)
        kept.remove(old)
        out.evicted.append(old.kf_id)
        _dropped(old, out)


def _dropped(k: Kept, out: Verdicts) -> None:
    """A kept view given up: one judged in the same pass is not kept after all."""
    out.place.pop(k.kf_id, None)
    if k.kf_id in out.status:
        out.status[k.kf_id] = REDUNDANT


def _evicted(variants: list[Kept], new_id: int, appearance: int, now: int) -> Kept:
    """The variant a full place gives up for ``new_id``: the one matched longest ago among the earlier
    views of the new one's appearance, else among appearances the place holds twice or more, else
    among all.

    Why by appearance first: a place's variants serve different appearances, and the one matched
    longest ago is often the only view of an appearance recorded less often (the nights of a map of
    mostly days); losing it loses the place for that appearance, losing an older view of the same one
    loses little. Why earlier views only: two views a session adds to one place (from poses a metre
    apart) both serve its appearance, which may have no other session yet."""
    others = [k for k in variants if k.kf_id != new_id]
    count = Counter(k.appearance for k in others)
    pool = [k for k in others if k.appearance == appearance and k.last_used < now] \
        or [k for k in others if count[k.appearance] > 1] or others
    return min(pool, key=lambda k: (k.last_used, k.kf_id))


def _near(T: np.ndarray, component: int, kept: list[Kept], radius: float, cos_max: float) -> list[Kept]:
    """Kept keyframes of ``component`` within ``radius`` whose optical axis is within the angle, nearest first."""
    if not kept:
        return []
    P = np.array([k.T_map_camera[:3, 3] for k in kept])
    Z = np.array([k.T_map_camera[:3, 2] for k in kept])
    d = np.linalg.norm(P - T[:3, 3], axis=1)
    ok = (d <= radius) & (Z @ T[:3, 2] >= cos_max) & np.array([k.component == component for k in kept])
    order = np.argsort(d)
    return [kept[i] for i in order if ok[i]]

