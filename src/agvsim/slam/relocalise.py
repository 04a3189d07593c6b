"""Global relocalisation over every finished submap, coarse to fine.

Looking for a scan everywhere mapped used to run branch and bound over each submap's full
pyramid (5 cm cells, every heading): some 200 fields and pyramids rebuilt from their occupied
cells and millions of root nodes, 6-22 s of CPU a try on Intel. Here each finished submap
keeps a *coarse field*, built once when it is finished (:func:`~.mapping.coarse_field`): its
likelihood field's maximum over each ``factor x factor`` block, as ``uint8`` rounded up
(``factor = 4``: 20 cm cells, a sixteenth of the cells at a byte each, 10-40 kB a submap:
memory follows the map, not the log). The search (:func:`global_search`):

1. branch and bound of a subsample of the scan over the coarse pyramid of every finished
   submap, the whole area and every heading (an angular step that moves the far points by one
   coarse cell); the pyramids (a few hundred kB) are built from the coarse fields per try in
   well under a millisecond each. Each submap's search is pruned by the ``refine``-th best
   coarse score so far, so the ``refine`` best submaps, each at its best coarse pose, remain;
2. those candidates, best first, are matched again on the submap's full pyramid (the loop
   detector's cache) in a window of 1.5 coarse cells and one coarse angular step round the
   coarse pose; a candidate whose coarse score does not beat the best fine score so far is
   skipped. The caller refines the winner with all the scan's points and decides.

The coarse score is the block maximum: at the coarse pose it bounds the fine score, but a
fine pose between two coarse ones can score more than both (dilating the blocks by one coarse
cell would make it a bound everywhere; measured on Intel, every busy submap then scores 1.0
and the right place ranks anywhere, while the block maxima rank it first on 10 of 12 scans).
So step 1 ranks and does not prove: ``refine`` candidates are kept, not one.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from agvsim.slam import scan_matching as sm
from agvsim.slam.frontend import Submap

__all__ = ["GlobalMatch", "coarse_pyramid", "covering", "global_search"]

F64 = NDArray[np.float64]
U8 = NDArray[np.uint8]

COARSE_LEVELS = 6  # top blocks of 32 coarse cells (6.4 m at 20 cm)


def coarse_pyramid(coarse: U8, levels: int = COARSE_LEVELS) -> NDArray[np.float32]:
    """Max pyramid of a coarse field, as floats in [0, 1] for the matcher."""
    return sm.max_pyramid(coarse.astype(np.float32) / np.float32(255.0), levels)


@dataclass(frozen=True)
class GlobalMatch:
    """The best place found: ``pose`` in ``submap``'s frame (the local frame it was built in),
    the subsample's score there on the full field and the coarse score it came from."""

    submap: int
    pose: F64
    score: float
    bound: float


def covering(submaps: Sequence[Submap]) -> list[Submap]:
    """The submaps with a coarse field, less each one whose keyframes all lie in the last one
    kept or the next one. Two submaps are active at a time and each keyframe goes into both,
    so about every other submap is kept and every keyframe mapped is still in one of them:
    the search looks at each place once instead of twice."""
    ok = [s for s in submaps if s.coarse is not None and s.coarse_factor >= 1]
    out: list[Submap] = []
    for k, s in enumerate(ok):
        near = set(out[-1].nodes) if out else set()
        if k + 1 < len(ok):
            near.update(ok[k + 1].nodes)
        if not near.issuperset(s.nodes):
            out.append(s)
    return out


def global_search(
    submaps: Sequence[Submap],
    points: F64,
    resolution_m: float,
    range_m: float,
    min_score: float,
    fine_pyramid: Callable[[Submap], np.ndarray],
    refine: int = 4,
    margin: float = 0.05,
) -> GlobalMatch | None:
    """Best place of ``points`` (n, 2, robot frame; a subsample of the scan) over the whole
    area and every heading of the finished ``submaps`` that carry a coarse field, or None
    when no candidate reaches ``min_score`` on its coarse score. ``range_m`` is the range that
    sets the angular steps (the scan's far points), ``fine_pyramid(s)`` the submap's full max
    pyramid (cached by the caller), ``refine`` how many coarse candidates are matched on it."""
    if len(points) == 0 or refine < 1:
        return None
    found: list[tuple[float, F64, Submap]] = []
    for s in covering(submaps):
        assert s.coarse is not None  # covering keeps only those
        res_c = s.coarse_factor * resolution_m
        pyr = coarse_pyramid(s.coarse)
        h, w = pyr.shape[1:]
        centre = np.array([s.ox + 0.5 * w * res_c, s.oy + 0.5 * h * res_c, 0.0])
        # prune by the refine-th best so far and by the best less margin: the refine best
        # submaps within margin of the best survive
        floor = found[refine - 1][0] if len(found) >= refine else min_score
        if found:
            floor = max(floor, found[0][0] - margin)
        pose, score = sm.branch_and_bound(
            pyr,
            s.ox,
            s.oy,
            res_c,
            points,
            centre,
            0.5 * max(h, w) * res_c,
            math.pi,
            sm.angular_step(res_c, range_m),
            floor,
        )
        if score > floor:
            found.append((score, pose, s))
            found.sort(key=lambda c: -c[0])
            del found[refine:]
            found = [c for c in found if c[0] > found[0][0] - margin]
    out: GlobalMatch | None = None
    step = 2.0 * sm.angular_step(resolution_m, range_m)
    for bound, pose, s in found:
        if out is not None and bound <= out.score:
            break  # its coarse score is under the best fine score so far
        res_c = s.coarse_factor * resolution_m
        fine, score = sm.branch_and_bound(
            fine_pyramid(s),
            s.ox,
            s.oy,
            resolution_m,
            points,
            pose,
            1.5 * res_c,
            sm.angular_step(res_c, range_m),
            step,
            0.0 if out is None else out.score,
        )
        if score > 0 and (out is None or score > out.score):
            out = GlobalMatch(s.index, fine, float(score), float(bound))
    return out
