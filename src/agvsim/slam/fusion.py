"""Fusion of scan matches with wheel odometry, by their noises learnt on the fly
(:class:`OdometryFusion`; used by :class:`~.frontend.Tracker`)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from agvsim.angles import wrap_angle, wrap_scalar
from agvsim.slam.se2 import between

if TYPE_CHECKING:
    from agvsim.slam.scale_pairs import PairScale

__all__ = ["OdometryFusion"]

F64 = NDArray[np.float64]

_MIN_SCALE_PATH_M = 5.0  # path in the window (m) before odometry's scale is estimated
_SCALE_RANGE = (0.8, 1.25)  # a scale estimate outside is clamped (a wrong wheel radius)
_SCALE_MEMORY = 1.0 - 1.0 / 3000.0  # weight of a scan's increment per scan since
_TURN_MIN_RAD = 0.2  # scans turning less are left out of the turn ratio (match noise)
_TURN_MIN_SCANS = 10


class OdometryFusion:
    """Weighs each scan match against the odometry prediction by their noises, estimated on
    the fly (no noise model of the robot needed).

    A match ``m_k`` is placed against the submap, so its error does not build up from scan to
    scan; odometry's does, as a random walk. Over the last ``window`` scans, the spread of the
    difference between the match's and odometry's increments is therefore
    ``v_1 = 2 s_m^2 + s_o^2`` for consecutive scans and ``v_L = 2 s_m^2 + L s_o^2`` over ``L``
    scans (robust spreads, separately for translation and heading), which gives the odometry's
    per-scan variance ``s_o^2`` and the match's ``s_m^2``. The pose kept is the prediction
    moved towards the match by the gain ``s_o^2 / (s_o^2 + s_m^2)``. That is deliberately
    more trusting of odometry than the steady-state Kalman gain for white match noise (about
    ``sqrt(s_o^2 / s_m^2)``): errors of matches against one submap are correlated from scan to
    scan, and the thesis maze's map IoU fell from 0.97 to 0.89 with the Kalman gain (mean of
    four recorded runs). For translation ``s_m^2`` is scaled per direction by how sharply the
    match is constrained there (the eigenvalues of its ``J^T J``, against their typical value),
    so along a corridor odometry carries the pose.
    A robot with good wheel odometry keeps it; one whose odometry slips follows its scans.

    Odometry's translation can be off by a constant factor (worn or mis-measured wheels, a
    tyre pressure): a bias, not noise, which the gain would let through since odometry looks
    precise from scan to scan. :meth:`scale` estimates that factor, the least-squares ``k``
    of ``m ~ k o`` over the lag-``lag`` translation increments of the raw matches ``m`` and
    of odometry ``o`` (robot frame; zero-mean match noise leaves it unbiased; a memory of
    a few thousand scans, longer than the noises' window), and :class:`~.frontend.Tracker`
    drives with odometry's increments scaled by it;
    the noises are learnt from the scaled increments. Those matches agree with the map that
    tracking drew, and over the first metres odometry draws it: with :attr:`pairs` set
    (:class:`~.graph_slam.GraphSlam` sets it by default) the scale is instead the one measured
    between raw scans a metre apart, free of that map (:mod:`agvsim.slam.scale_pairs`).

    Until it is :meth:`ready`, the pose is odometry's alone (and :class:`~.graph_slam.GraphSlam`
    processes those first scans again with the learnt noises, :meth:`preset`).

    The two lags cannot tell the match's noise from an odometry error that does not build up
    (odometry smoothed or lagging: off on every turn, right again after it): both are the same
    at every lag, and all of it would be put on the match, so the fusion would trust that
    odometry fully. A match that fits is not off by more than about a cell or a degree, so
    the learnt match spread is capped at ``match_ceilings`` (std) and the rest is odometry's
    (:meth:`estimate`).

    That capped spread is still one figure for every scan, and a robust one: where most scans
    go straight it shows the straight scans. :meth:`estimate_turn_ratio` learns the part of
    odometry's heading error that follows the turn (std per radian turned, from the scans
    that turned at least ``_TURN_MIN_RAD``), with which tracking widens its heading window
    at a turn (:meth:`~.odometry_check.OdometryCheck.windows`) and, with ``turn_gain``,
    :meth:`fuse` adds ``(ratio * turn)^2`` to odometry's heading variance: where odometry
    lags each turn (smoothed over sparse scans), the capped match spread above still left it
    6 % of every heading correction in a turn (a gain of 0.94 on the simulated 1 Hz fault),
    turn after turn, and the map bent."""

    def __init__(
        self,
        window: int,
        lag: int,
        floors: tuple[float, float, float] = (0.0, 0.0, 0.0),
        match_ceilings: tuple[float, float] = (math.inf, math.inf),
        turn_gain: bool = False,
    ) -> None:
        self.window, self.lag = window, lag
        # odometry's heading variance in fuse() grows with the turn, by turn_ratio (learnt)
        self.turn_gain = turn_gain
        self.floors = floors  # std: m per m, rad per rad, rad per m (TrackingConfig.odom_floor_*)
        # std: m, rad (TrackingConfig.match_ceiling_*): see estimate()
        self.match_ceilings = match_ceilings
        self._preset = False
        self.matches: list[F64] = []
        self.odoms: list[F64] = []
        self.sharp: list[float] = []
        self._k = (1.0, 1.0, 1.0, 1.0)  # see estimate()
        self._scale = 1.0  # see scale()
        # odometry's scale measured scan to scan (GraphSlam sets it): the scale, when set
        self.pairs: PairScale | None = None
        self._scale_sums = (0.0, 0.0, 0.0)  # sum m.o, sum o.o, path (m), with forgetting
        self._count = 0
        self.turn_ratio = 0.0  # see estimate_turn_ratio()
        self._raw: F64 | None = None
        self._last_odom: F64 | None = None

    def floor_variance(self, step: F64) -> tuple[float, float]:
        """Odometry's least per-scan variance (translation, heading) for an odometry
        increment ``step`` (3,): its physics, not what the run showed (:class:`TrackingConfig`
        ``odom_floor_*``). Regular motion between sparse scans can make the learnt spread
        vanish; scans must still correct odometry in proportion to how far it drove."""
        dist, turn = math.hypot(step[0], step[1]), abs(wrap_scalar(step[2]))
        f_m, f_rr, f_rm = self.floors
        return (f_m * dist) ** 2, (f_rr * turn + f_rm * dist) ** 2

    def match_variance(self) -> tuple[float, float] | None:
        """The matches' per-scan variance (translation, heading), None until learnt."""
        if not (self._preset or self.ready()):
            return None
        s_o, s_m, k_rot, s_or = self._k
        return s_m, s_or * (1.0 - k_rot) / max(k_rot, 1e-12)

    def fuse(
        self, guess: F64, match: F64, hessian: F64, step: F64 | None = None, learn: bool = True
    ) -> F64:
        """The fused pose; records ``match`` unless ``learn`` is False (call :meth:`add`
        with the odometry after). ``step`` is the odometry increment behind ``guess`` (for
        the noise floors)."""
        self._raw = np.asarray(match, np.float64).copy() if learn else None
        w, v = np.linalg.eigh(hessian[:2, :2])
        w = np.maximum(w, 0.0)
        self.sharp.append(float(math.sqrt(w[0] * w[1])))
        if not self.ready() and not self._preset:
            # learning the noises: odometry alone builds the map, so that the matches against
            # it show odometry's drift (GraphSlam then processes these scans again)
            return guess.copy()
        if self.ready() and self._count % 10 == 0:
            if self.pairs is None:
                self._scale = self.estimate_scale()
            self._k, self.turn_ratio = self.learn()
        s_o, s_m, k_rot, s_or = self._k
        if step is not None:
            f_t, f_r = self.floor_variance(step)
            if f_t > s_o:
                s_o = f_t
            # odometry's heading error that follows the turn (learnt), on top of its floor
            v_turn = self.turn_variance(step[2]) if self.turn_gain else 0.0
            if f_r > s_or or v_turn > 0.0:
                s_mr = s_or * (1.0 - k_rot) / max(k_rot, 1e-12)
                v_r = max(f_r, s_or) + v_turn
                k_rot = v_r / (v_r + s_mr)
        ref = float(np.median(self.sharp))
        d = v.T @ (match[:2] - guess[:2])
        d *= s_o / (s_o + s_m * ref / np.maximum(w, 1e-9 * ref + 1e-12))
        out = guess.copy()
        out[:2] = guess[:2] + v @ d
        out[2] = guess[2] + k_rot * wrap_scalar(match[2] - guess[2])
        return out

    def turn_variance(self, turn: float) -> float:
        """Odometry's heading variance (rad^2) from a turn of ``turn`` rad: ``(ratio * turn)^2``
        with the ratio last learnt (:meth:`estimate_turn_ratio`; the search window and, with
        ``turn_gain``, :meth:`fuse` add it)."""
        return (self.turn_ratio * abs(wrap_scalar(turn))) ** 2

    def estimate_turn_ratio(self) -> float:
        """Odometry's heading error per radian turned (std), from the scans so far."""
        m, o = self._history()
        if len(m) < 3:
            return 0.0
        return _turn_ratio(m, o, _spread(m, o, 1, self.scale())[1])

    def learn(self) -> tuple[tuple[float, float, float, float], float]:
        """:meth:`estimate` and :meth:`estimate_turn_ratio` together (noises, turn ratio),
        sharing the arrays and the lag-1 spread they both read."""
        m, o = self._history()
        v1 = _spread(m, o, 1, self.scale())
        return self._estimate(m, o, v1), (_turn_ratio(m, o, v1[1]) if len(m) >= 3 else 0.0)

    def _history(self) -> tuple[F64, F64]:
        """The raw matches and odometry poses kept, as ``(n, 3)`` arrays of equal length."""
        n = min(len(self.matches), len(self.odoms))
        return np.asarray(self.matches[-n:]), np.asarray(self.odoms[-n:])

    def scale(self) -> float:
        """Odometry's translation scale as last estimated: :attr:`pairs`' when set, else
        from the matches against the submap (1 until :meth:`ready`)."""
        return self._scale if self.pairs is None else self.pairs.scale

    def estimate_scale(self) -> float:
        """``sum(m . o) / sum(o . o)`` over lag increments (class docstring), each weighed
        by ``_SCALE_MEMORY`` per scan since (a wheel's scale changes slowly: a memory longer
        than the noises' window averages out the matches' noise and the places where they
        are weak); 1 while the sums hold under ``_MIN_SCALE_PATH_M`` of path or ``k`` is
        within 3 standard errors of 1 (odometry's noise, not a bias), clamped to
        ``_SCALE_RANGE``."""
        s_mo, s_oo, path = self._scale_sums
        if path < _MIN_SCALE_PATH_M or s_oo <= 0.0:
            return 1.0
        k = s_mo / s_oo
        # standard error of k: two matches' noise per increment, increments overlapping lag
        # times (the match variance as last learnt)
        if abs(k - 1.0) <= 3.0 * math.sqrt(2.0 * self._k[1] * self.lag / s_oo):
            return 1.0
        return min(max(k, _SCALE_RANGE[0]), _SCALE_RANGE[1])

    def _update_scale_sums(self) -> None:
        lag = self.lag
        if len(self.matches) <= lag:
            return
        dm = between(self.matches[-1 - lag], self.matches[-1])[:2]
        do = between(self.odoms[-1 - lag], self.odoms[-1])[:2]
        s_mo, s_oo, path = self._scale_sums
        f = _SCALE_MEMORY
        self._scale_sums = (
            f * s_mo + float(dm @ do),
            f * s_oo + float(do @ do),
            f * path + math.hypot(do[0], do[1]) / lag,
        )

    def ready(self) -> bool:
        """Enough scans taken on the move to estimate the noises."""
        return len(self.matches) >= self.lag + 30

    def preset(self, k: tuple[float, float, float, float], turn_ratio: float = 0.0) -> None:
        """Start from noises (see :meth:`estimate`) and a turn ratio (:meth:`estimate_turn_ratio`)
        learnt earlier until enough scans come."""
        self._k, self._preset, self.turn_ratio = k, True, turn_ratio

    def odometry_variance(self) -> tuple[float, float] | None:
        if not (self._preset or self.ready()):
            return None
        return self._k[0], self._k[3]

    def add(self, odom: F64) -> None:
        """Record the scan's odometry beside its raw match (scans without a match, and scans
        taken standing still, are left out)."""
        last, self._last_odom = self._last_odom, odom.copy()
        if self._raw is None:
            return
        if last is not None:
            step = between(last, odom)
            if math.hypot(step[0], step[1]) < 1e-3 and abs(step[2]) < 1e-3:
                self._raw = None  # standing still: odometry has nothing to drift by
                return
        self.matches.append(self._raw)
        self.odoms.append(odom.copy())
        self._raw = None
        self._count += 1
        if self.pairs is None:  # else the scale is the pairs' (scale())
            self._update_scale_sums()
        keep = self.window + self.lag + 1
        if len(self.odoms) > keep:
            del self.odoms[0]
        if len(self.matches) > keep:
            del self.matches[0]
        if len(self.sharp) > self.window:
            del self.sharp[0]

    def estimate(self) -> tuple[float, float, float, float]:
        """``(odometry translation var, match translation var, heading gain, odometry heading
        var)`` per scan, from the scans so far."""
        m, o = self._history()
        return self._estimate(m, o, _spread(m, o, 1, self.scale()))

    def _estimate(
        self, m: F64, o: F64, v1: tuple[float, float]
    ) -> tuple[float, float, float, float]:
        """:meth:`estimate` from the history ``m``, ``o`` and its lag-1 spread ``v1``."""
        lag = min(self.lag, max((len(m) - 1) // 3, 2))
        vl = _spread(m, o, lag, self.scale())
        out = []
        for a, b, cap in zip(v1, vl, self.match_ceilings, strict=True):
            s_o = max(b - a, 0.0) / (lag - 1)
            s_m = max(a - s_o, 1e-12) / 2.0
            if s_m > cap**2:
                # more than a match can be off: odometry's error that does not build up
                # (smoothed or lagging odometry is off on every turn and right again after
                # it); it is odometry's per-scan error all the same
                s_o, s_m = s_o + 2.0 * (s_m - cap**2), cap**2
            out.append((s_o, s_m))
        (so_t, sm_t), (so_r, sm_r) = out
        return so_t, sm_t, so_r / (so_r + sm_r), so_r


def _turn_ratio(m: F64, o: F64, base_var: float) -> float:
    """Robust std of odometry's heading error per radian it turned, scan to scan, over the
    scans that turned at least ``_TURN_MIN_RAD`` (their error's square less ``base_var``, the
    spread of scans that did not turn); 0 with fewer than ``_TURN_MIN_SCANS`` such scans."""
    do = between(o[:-1], o[1:])
    dm = between(m[:-1], m[1:])
    turn = np.abs(wrap_angle(do[:, 2]))
    sel = turn >= _TURN_MIN_RAD
    if int(sel.sum()) < _TURN_MIN_SCANS:
        return 0.0
    e = wrap_angle(dm[sel, 2] - do[sel, 2])
    excess = np.sqrt(np.maximum(e * e - base_var, 0.0))
    return float(1.4826 * np.median(excess / turn[sel]))


def _spread(m: F64, o: F64, lag: int, scale: float = 1.0) -> tuple[float, float]:
    """Robust variances (translation per axis, heading) of the difference between the
    increments of ``m`` and ``o`` (translation times ``scale``) over ``lag`` samples."""
    do = between(o[:-lag], o[lag:])
    do[:, :2] *= scale
    e = between(do, between(m[:-lag], m[lag:]))
    mad = 1.4826 * np.median(np.abs(e), axis=0)
    return float(np.mean(mad[:2] ** 2)), float(mad[2] ** 2)
