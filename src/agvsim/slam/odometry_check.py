"""Odometry that tracking can doubt: stalls, jumps and slips, found by scan matching.

Tracking predicts each scan's pose from odometry. Wheel odometry can freeze for a few messages
and then jump by the motion it missed (a stalled driver), slip, or glitch. Applied scan to scan
as ``x_pred = x_prev * (o_prev^-1 o_now)``, a freeze loses the motion (the matcher follows the
real motion, if its window allows) and the jump then adds it a second time: the heading ends
outside every search window. So :class:`OdometryCheck` keeps a *reference*: the last scan whose
match agreed with odometry, ``(x_ref, o_ref)``. Odometry is relative, so the prediction from the
reference, ``x_ref * (o_ref^-1 o_now)``, is right after a freeze ends however long it lasted;
the scan-to-scan prediction is right after a slip (odometry moved, the robot did not). Both are
offered to the matcher, which keeps the one the scan fits better (:meth:`candidates`); where
they fit alike (along a corridor) an encoder stall decides (:attr:`OdometryCheck.preferred`,
below): while odometry stands still on the move the last tracked motion, once it moves again
after nothing but encoder stalls the prediction from the reference.

Odometry *stalled* when it reports exactly no motion while tracking saw the robot move at
the scan before (``moving_m``, ``moving_rad``). Then the last tracked motion is offered as a
third prediction, and the scan counts as one that refuted odometry. Only an *encoder stall*
(``encoder_stall``) decides ties and keeps odometry edges across it: one where odometry
itself moved at the scan before as well (wheels decelerate, encoders do not stop dead), and
the scans after it while odometry stays frozen and tracking still moves. Tracking's jitter
of a centimetre or half a degree on a robot at rest is no such stall (ACES stands still for
a third of its scans, and tracking alone called 210 of them stalls), while a robot that
starts a turn from rest under a frozen odometry still gets the last motion offered.

Otherwise a match *disagrees* with the prediction (:meth:`disagrees`) when it lies further from
it than ``gate_sigmas`` of their combined spread (odometry's learnt per-scan variance times the
scans since the reference, plus the match's), with floors of two cells and three degrees,
**and** the scan fits clearly better at the match than at the prediction (``margin`` in mean
likelihood): along a featureless corridor the two fit equally and odometry keeps the pose.
While odometry disagrees, the reference stays where odometry was last right; after
``max_doubt_scans`` in a row the reference moves on regardless (odometry slipped for good and
is right again from here).

The heading and translation search windows grow with that same spread (:meth:`windows`):
``window_sigmas`` standard deviations of the prediction, between the configured narrow window
and ``max_window_rad`` / the wide window. The heading's spread also has a part in proportion to
the turn the prediction makes (``turn_windows``; odometry's error per radian turned, learnt by
:meth:`~.fusion.OdometryFusion.estimate_turn_ratio`): odometry that lags or is smoothed
between sparse scans is off by a share of every turn and right on the straight, which a
spread learnt over all scans (robustly: most scans go straight) does not show.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from agvsim.slam.se2 import between, compose

__all__ = ["DoubtConfig", "OdometryCheck"]

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class DoubtConfig:
    """Knobs of :class:`OdometryCheck` (metres, radians, mean likelihood); ``enabled=False``
    trusts odometry blindly (scan-to-scan prediction, fixed windows)."""

    enabled: bool = True

    gate_sigmas: float = 4.0
    min_gate_m: float = 0.1  # disagreements smaller than this are matching noise
    min_gate_rad: float = math.radians(3.0)
    margin: float = 0.05  # the scan must fit this much better at the match than at the guess
    moving_m: float = 0.01  # tracked motion per scan above which an unchanged odometry stalled
    moving_rad: float = math.radians(0.5)
    max_doubt_scans: int = 20
    window_sigmas: float = 3.0
    max_window_m: float = 0.4
    max_window_rad: float = math.radians(45.0)
    turn_windows: bool = True  # the heading window grows with the turn predicted (windows())


class OdometryCheck:
    """The reference scan and the count of scans since it (module docstring)."""

    def __init__(self, cfg: DoubtConfig) -> None:
        self.cfg = cfg
        self.ref_pose: F64 | None = None
        self.ref_odom: F64 | None = None
        self.since_ref = 0  # scans since the reference (1: the previous scan is the reference)
        self.doubted = 0  # scans in a row whose match disagreed with odometry
        self.n_doubted = 0  # in all
        self.stall = False  # odometry did not change while the robot was moving
        # ... and it moved itself at the scan before, or that scan was one: see the docstring
        self.encoder_stall = False
        self.frozen = False  # odometry did not change at all since the scan before
        self.last_pose: F64 | None = None
        self.last_odom: F64 | None = None
        self.last_motion: F64 | None = None  # tracked motion of the last scan
        self._moving = False
        self._odom_moving = False  # odometry's own increment at the scan before moved
        # every scan since the reference was a stall (none where odometry moved wrongly)
        self.stalls_only = True
        # index into candidates() of the prediction that wins ties (None: the first)
        self.preferred: int | None = None

    def candidates(self, prev_pose: F64, prev_odom: F64, odom: F64) -> list[F64]:
        """Predictions of the scan's pose: scan to scan; the last tracked motion again if
        odometry stalled (``stall``); and from the reference if that is an older scan. Sets
        ``preferred``, the one that wins ties (module docstring)."""
        u = between(prev_odom, odom)
        out = [compose(prev_pose, u)]
        self.preferred = None
        if not self.cfg.enabled:
            return out
        self.frozen = bool(np.all(u == 0.0))
        self.stall = self.frozen and self._moving
        self.encoder_stall = self.stall and (self.encoder_stall or self._odom_moving)
        if self.stall and self.last_motion is not None:
            out.append(compose(prev_pose, self.last_motion))
            if self.encoder_stall:
                self.preferred = 1  # a stalled encoder, not a robot stopped dead
        if self.ref_pose is not None and self.ref_odom is not None and self.since_ref > 1:
            out.append(compose(self.ref_pose, between(self.ref_odom, odom)))
            if self.stalls_only and not self.frozen:
                # odometry moves again after a stall: it jumped by what it missed, and is
                # right from the reference
                self.preferred = len(out) - 1
        return out

    def spread(self, odom_var: tuple[float, float] | None) -> tuple[float, float] | None:
        """Std of the prediction (translation m, heading rad) from odometry's per-scan
        variances and the scans since the reference; None while they are unknown."""
        if odom_var is None:
            return None
        n = max(self.since_ref, 1)
        return math.sqrt(n * odom_var[0]), math.sqrt(n * odom_var[1])

    def windows(
        self,
        odom_var: tuple[float, float] | None,
        base_m: float,
        base_rad: float,
        turn_var: float = 0.0,
    ) -> tuple[float, float]:
        """Search half-widths: ``window_sigmas`` stds of the prediction, at least the base;
        ``turn_var`` (rad^2) is heading variance added for the turn this scan made."""
        s = self.spread(odom_var)
        if s is None or not self.cfg.enabled:
            return base_m, base_rad
        k = self.cfg.window_sigmas
        s_rad = math.sqrt(s[1] ** 2 + (turn_var if self.cfg.turn_windows else 0.0))
        return (
            min(max(base_m, k * s[0]), max(self.cfg.max_window_m, base_m)),
            min(max(base_rad, k * s_rad), max(self.cfg.max_window_rad, base_rad)),
        )

    def disagrees(
        self,
        guess: F64,
        match: F64,
        score_match: float,
        score_guess: float,
        odom_var: tuple[float, float] | None,
        match_var: tuple[float, float] | None,
    ) -> bool:
        """Whether the match refutes the odometry prediction (module docstring); a stall
        always does."""
        if not self.cfg.enabled:
            return False
        if self.stall:
            return True
        if score_match - score_guess < self.cfg.margin:
            return False
        d = between(guess, match)
        s = self.spread(odom_var) or (0.0, 0.0)
        mv = match_var or (0.0, 0.0)
        k = self.cfg.gate_sigmas
        gate_m = max(self.cfg.min_gate_m, k * math.sqrt(s[0] ** 2 + mv[0]))
        gate_rad = max(self.cfg.min_gate_rad, k * math.sqrt(s[1] ** 2 + mv[1]))
        return math.hypot(d[0], d[1]) > gate_m or abs(d[2]) > gate_rad

    def _moved(self, step: F64) -> bool:
        c = self.cfg
        return math.hypot(step[0], step[1]) >= c.moving_m or abs(step[2]) >= c.moving_rad

    def accept(self, pose: F64, odom: F64, doubted: bool) -> None:
        """Record the scan's pose: it becomes the reference unless odometry was doubted (for
        fewer than ``max_doubt_scans`` in a row)."""
        odom = np.asarray(odom, np.float64)
        if self.last_pose is not None and self.last_odom is not None:
            self.last_motion = between(self.last_pose, pose)
            self._moving = self._moved(self.last_motion)
            self._odom_moving = self._moved(between(self.last_odom, odom))
        self.last_pose, self.last_odom = pose.copy(), odom.copy()
        if doubted:
            # a frozen odometry is right again once it moves (it jumps by what it missed,
            # however long it froze): only scans where it moved wrongly count towards
            # max_doubt_scans (a slip for good)
            self.doubted += 0 if self.frozen else 1
            self.n_doubted += 1
            self.stalls_only = self.stalls_only and self.encoder_stall
        else:
            self.doubted = 0
        if self.ref_pose is None or not doubted or self.doubted >= self.cfg.max_doubt_scans:
            self.ref_pose, self.ref_odom = pose.copy(), odom.copy()
            self.since_ref = 1
            self.stalls_only = True
            if doubted:
                self.doubted = 0
        else:
            self.since_ref += 1
