"""Tracking: measurements of one frame -> filtered objects with stable ids."""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import replace

import cv2
import numpy as np
from filterpy.kalman import KalmanFilter

from tracker.boxfit import SizePrior, ViewShades
from tracker.config import TrackConfig
from tracker.geometry import Rect, rectangle_corners, wrap_angle_deg
from tracker.height import HeightEstimate
from tracker.kalman import ANGLE, LENGTH, VX, VY, WIDTH, X, Y, make_filter, set_interval
from tracker.measure import KnownPart, Measurement
from tracker.poses import TrackedObject
from tracker.shades import FaceShades, ShadeEstimate


class Track:
    def __init__(self, track_id: int, m: Measurement, t_ns: int, cfg: TrackConfig,
                 height_vote_step_mm: float | None = None) -> None:
        """``height_vote_step_mm``: with --part-height auto, how far apart the views that vote on its
        height are (see HeightEstimate; None: its height is given, or none)."""
        self.id = track_id
        # --part-height auto: what its views tell of its height (None: heights given, or none).
        self.height = None if height_vote_step_mm is None else HeightEstimate(cfg, height_vote_step_mm)
        # With measure.learn_shades: its side shades as its views tell them (--part-height auto: its
        # boxes' at the height it is estimated or voted to have, see _learn_shades).
        self.shades: ShadeEstimate | None = None
        self._shades_mm: float | None = None  # the height of the boxes they were learnt on (see _learn_shades)
        if self.height is not None:
            self.height.add(m, *m.seen_at_mm)
            # Its pose at the height its first view puts first.
            m = replace(m, rect=self.height.rect(m))
        self.kf = _filter_from(m, cfg)
        self.t_ns = t_ns
        self.missed = 0  # consecutive frames without any blob
        self.hits = 1  # frames with a measurement
        self.seen_ns = t_ns  # time of the last frame with a blob (clipped or not)
        self.age_frames = 0  # frames since the last (unclipped) measurement
        # Whether the arm may take it: False while it touches or lies on another part.
        self.pickable = m.pickable
        # Since when its blobs have had another size than the part (partly hidden, or joined by another).
        self.odd_size_since_ns: int | None = None
        # Consecutive measurements of one size: a part whose size has settled can be checked against it
        # (a growing sliver, as a part comes into view or leaves its start position, has not).
        self.same_size = 0
        # How much its measured sizes scatter (mm^2, a running mean): real segmentation is noisier
        # than rendered scenes, and a size jump is judged against the part's own scatter.
        self.size_var_mm2 = 0.0
        # How far its measured centres scatter about its predictions (mm^2, a running mean likewise): a
        # young track's velocity is still rough, a settled one's predictions are near every blob.
        self.position_var_mm2 = 0.0
        # A part first seen as a piece of a blob (see split.py) is reported once its size has settled:
        # the cuts of odd blobs (a part leaving the ghost of its start position) give growing slivers.
        self.tentative = m.piece
        # Filter states after the last few updates, oldest first: the blobs just before a size jump
        # were already partly hidden, so the state is taken back to before them (see rewind).
        self._history: deque = deque(maxlen=cfg.rewind_frames + 1)
    @property
    def position(self) -> np.ndarray:
        return self.kf.x[[X, Y], 0]

    def predict(self, t_ns: int, cfg: TrackConfig) -> None:
        if t_ns > self.t_ns:
            set_interval(self.kf, (t_ns - self.t_ns) / 1e9, cfg)
            self.kf.predict()
            self.t_ns = t_ns
            self._normalise()

    def size_jump(self, m: Measurement, cfg: TrackConfig, fraction: float | None = None) -> float:
        """How much larger (> 0) or smaller (< 0) the blob is than the part, beyond the tolerance (the
        larger of ``size_jump_mm``, ``fraction`` of the side, by default ``size_jump_fraction``, and
        ``size_jump_sigmas`` times its sizes' scatter); else 0."""
        fraction = cfg.size_jump_fraction if fraction is None else fraction
        scatter_mm = cfg.size_jump_sigmas * math.sqrt(self.size_var_mm2)
        worst = 0.0
        for d, p in zip(self._size_residuals(m), sorted(self.kf.x[[LENGTH, WIDTH], 0]), strict=True):
            if abs(d) > max(cfg.size_jump_mm, fraction * p, scatter_mm) and abs(d) > abs(worst):
                worst = d
        return worst

    def aside(self, m: Measurement, cfg: TrackConfig) -> float:
        """How much larger (> 0) or smaller (< 0) than the part a blob lying aside from its predicted centre
        is (0: not aside, or of its size): farther than a size jump (``size_jump_mm``, or ``size_jump_sigmas``
        times the scatter of its blobs about its predictions), and either a piece cut from a blob or a
        whole blob of another size by more than ``size_jump_mm`` on a side (and ``size_jump_sigmas`` times
        the scatter of its sizes: the CCTV footage's boxes, 4.4 mm a pixel, scatter by about 3 mm). Such
        a blob is not the part:

        - a piece of the part beside it (its blob cut where it was whole), fitted at the size it was lent.
          Its own size need not say so: a side the cut left open is held by the lent size alone (random
          scene 37 under a lamp: noise on a faint face cut the blob in three, and the largest piece, at
          the part's size 11 mm aside, threw its velocity 570 mm/s off);
        - the part with something beside it that the size check lets pass, as within its fraction of the
          part's size (random scene 42 under a lamp: a 60 mm box's dim long face, partly segmented, made
          blobs 5.6 and 4.0 mm larger and 10 mm aside; taken, their scatter let blobs 7 mm larger in).

        A young track's predictions scatter (two parts entering the view touching: 5-15 mm) and allow as
        much. A part pushed aside (a hand, a guide rail) keeps its size, and is followed."""
        allowed_mm = max(cfg.size_jump_mm, cfg.size_jump_sigmas * math.sqrt(self.position_var_mm2))
        if math.dist(self.position, (m.rect.x_mm, m.rect.y_mm)) <= allowed_mm:
            return 0.0
        return -cfg.size_jump_mm if m.piece else float(self.size_jump(m, cfg, fraction=0.0))

    def _size_residuals(self, m: Measurement) -> np.ndarray:
        """Blob minus part, shorter sides first (mm). A piece cut from a blob may be a piece of the part,
        and its fit, lent the part's size, is pulled to it: each side is the shorter of the fit's and
        the one its view tells on its own (a piece of a 76 mm box that noise cut off its blob, fitted at
        75.9 mm 20 mm off, broke the track's velocity). Only for pieces: a whole blob's own size is
        noisier than its fit's (a 90 mm part at 320x240 told 96)."""
        size = np.sort([m.rect.length_mm, m.rect.width_mm])
        if m.piece and m.own_size_mm is not None:
            size = np.minimum(size, np.sort(m.own_size_mm))
        return size - np.sort(self.kf.x[[LENGTH, WIDTH], 0])

    def rewind(self, t_ns: int, cfg: TrackConfig) -> None:
        """Back to the state of ``rewind_frames`` updates ago, predicted to ``t_ns``."""
        if len(self._history) < 2:
            return
        then_ns, x, p = self._history[0]
        self.kf.x, self.kf.P, self.t_ns = x.copy(), p.copy(), then_ns
        self.predict(t_ns, cfg)
        self._history.clear()

    def into_frame_moving_at(self, vx_mm_s: float, vy_mm_s: float) -> None:
        """From now on tracked in a frame moving at (vx, vy) mm/s that lay on the world's at its last update
        (the belt's, once its motion is measured): its velocity is that much less; earlier states, in
        the world's frame, are no longer gone back to."""
        self.kf.x[VX, 0] -= vx_mm_s
        self.kf.x[VY, 0] -= vy_mm_s
        self._history.clear()

    def restart(self, m: Measurement, cfg: TrackConfig) -> None:
        """Start the filter again from this blob: the part's size was wrong (a young track born of a sliver,
        or an established one whose blobs have kept another size for max_coast_s)."""
        self.kf = _filter_from(m, cfg)
        self.odd_size_since_ns = None
        # Its views so far were of another size (a sliver), and so told another shape.
        if self.height is not None:
            self.height = HeightEstimate(cfg, self.height.vote_step_mm)
        self.shades = None

    def settled(self, cfg: TrackConfig) -> bool:
        return self.same_size >= cfg.coast_min_hits

    def update(self, m: Measurement, cfg: TrackConfig) -> None:
        self.same_size = self.same_size + 1 if not self.size_jump(m, cfg) else 0
        a = cfg.size_scatter_weight
        self.size_var_mm2 = (1 - a) * self.size_var_mm2 + a * float(np.mean(self._size_residuals(m) ** 2))
        self.pickable = m.pickable
        r = m.rect
        if self.height is None and m.view_shades is not None:  # its height given
            self._add_shades(m.view_shades, cfg)
        if self.height is not None:
            leading = self.height.leading_mm, self.height.flat, self.height.voting
            self.height.add(m, *m.seen_at_mm)
            r = self.height.rect(m)
            self._learn_shades(m, cfg, leading[0])
            if leading != (self.height.leading_mm, self.height.flat, self.height.voting):
                # Another height leads the vote (or it is decided): the part's footprint is where that
                # height puts it, and of the size it needs, not the last one's.
                self._reseat(r, cfg)
        predicted = float(self.kf.x[ANGLE, 0])
        # The rectangle's two axes are both candidates for the tracked "long side":
        # take the one nearer the prediction, so near-square parts do not flip by 90 deg.
        d_long = wrap_angle_deg(r.angle_deg - predicted)
        d_short = wrap_angle_deg(r.angle_deg + 90.0 - predicted)
        swapped = abs(d_long) > abs(d_short)
        # The size this view tells on its own: a box fitted with the track's size lent is pulled towards
        # it, and that pull is the track's own knowledge, not news.
        length, width = m.own_size_mm if m.own_size_mm is not None and r is m.rect else (r.length_mm, r.width_mm)
        if not swapped:
            z = np.array([r.x_mm, r.y_mm, predicted + d_long, length, width])
        else:
            z = np.array([r.x_mm, r.y_mm, predicted + d_short, width, length])
        innovation_mm = math.dist(self.position, z[:2])
        self.position_var_mm2 = (1 - a) * self.position_var_mm2 + a * innovation_mm**2
        r_cov = self.kf.R if m.size_cov_mm2 is None else self._noise_of(m, swapped, cfg)
        shape = None if self.height is None else self.height.shape()
        if shape is not None:
            # The size is the one all views so far tell together with the height, not this view's.
            order = [1, 0] if swapped else [0, 1]
            z[3:] = shape[0][order]
            r_cov = r_cov.copy()
            r_cov[3:, 3:] = shape[1][np.ix_(order, order)] + np.eye(2) * cfg.known_size_sigma_mm**2
        self.kf.update(z.reshape(5, 1), R=r_cov)
        self._normalise()
        self._history.append((self.t_ns, self.kf.x.copy(), self.kf.P.copy()))

    def _learn_shades(self, m: Measurement, cfg: TrackConfig, lead_mm: float | None) -> None:
        """Add what view ``m`` tells of the part's side shades at its estimated height, or while voted on
        at the height leading the vote (the pose's): lent to the fits between votes, whose views refine
        the height once the vote decides (HeightEstimate._replay_between_votes; without them those views
        scattered, the tests' 10 mm box at 10 deg 0.58 mm off once converged). None for a flat part, nor
        before a height leads. Shades learnt at a height more than track.view_height_sigma_mm from the
        one now estimated or leading are forgotten: a box of another height passes for the part with
        other shades (the shades an 8 mm box's 10 mm boxes learnt held its refinement at 9.2 mm). A
        view tells them only if its box (at ``lead_mm``, the height that led before it) is of that
        height, to the same limit (the view that decides a vote for another height: its box was the
        old lead's). The vote's own fits of every height are lent none (a flat part's 5-10 mm boxes,
        lent a side as bright as the top, led its vote)."""
        height = self.height.height_mm if not self.height.voting else self.height.leading_mm
        if self.height.flat or not height:
            self.shades = None
            return
        if self._shades_mm is not None and abs(self._shades_mm - height) > cfg.view_height_sigma_mm:
            self.shades = None  # learnt on boxes of another height
        if m.view_shades is not None and (lead_mm is None or abs(lead_mm - height) <= cfg.view_height_sigma_mm):
            self._add_shades(m.view_shades, cfg)
            self._shades_mm = height

    def _add_shades(self, view: ViewShades, cfg: TrackConfig) -> None:
        if self.shades is None:
            self.shades = ShadeEstimate(cfg)
        self.shades.add(view)

    def _reseat(self, r: Rect, cfg: TrackConfig) -> None:
        """Take the position and size of rectangle ``r`` as the part's (its sides in the filter's order):
        measured at another height, the footprint is elsewhere and of another size."""
        self.kf.x[[X, Y], 0] = r.x_mm, r.y_mm
        size = [LENGTH, WIDTH]
        sides = sorted((r.length_mm, r.width_mm), reverse=bool(self.kf.x[LENGTH, 0] >= self.kf.x[WIDTH, 0]))
        self.kf.x[size, 0] = sides
        self.kf.P[np.ix_(size, size)] = np.eye(2) * cfg.size_sigma_mm**2
        others = [i for i in range(len(self.kf.x)) if i not in size]
        self.kf.P[np.ix_(size, others)] = 0.0
        self.kf.P[np.ix_(others, size)] = 0.0

    def _noise_of(self, m: Measurement, swapped: bool, cfg: TrackConfig) -> np.ndarray:
        """The measurement's noise covariance: a box's size counts as much as its view tells (see BoxFit)."""
        order = [1, 0] if swapped else [0, 1]
        r_cov = self.kf.R.copy()
        r_cov[3:, 3:] = _size_noise(m, cfg)[np.ix_(order, order)]
        return r_cov

    def known(self, cfg: TrackConfig, offset_mm: tuple[float, float] = (0.0, 0.0)) -> KnownPart:
        """Where the part is expected (as last predicted; in the world frame: its own, moved by
        ``offset_mm``) and its size as known so far."""
        x = self.kf.x[:, 0].copy()
        x[[X, Y]] += offset_mm
        sigma = np.sqrt(np.maximum(np.diag(self.kf.P)[[LENGTH, WIDTH]], cfg.known_size_sigma_mm**2))
        size = SizePrior(float(x[LENGTH]), float(x[WIDTH]), *map(float, sigma))
        if self.height is None:
            return KnownPart(float(x[X]), float(x[Y]), size, shades=self._lent_shades())
        if self.height.flat:
            return KnownPart(float(x[X]), float(x[Y]), size, flat=True)
        if self.height.voting:
            return KnownPart(float(x[X]), float(x[Y]), size, last_vote_mm=self.height.last_vote_mm,
                             vote_step_mm=self.height.vote_step_mm, leading_mm=self.height.leading_mm,
                             shades=self._lent_shades())
        # Being refined: the size and height as the track's views tell them together.
        (length, width, _), cov = self.height.shape()
        sigma = np.sqrt(np.maximum(np.diag(cov)[:2], cfg.known_size_sigma_mm**2))
        if width > length:
            length, width = width, length
            sigma = sigma[::-1]
        size = SizePrior(float(length), float(width), float(sigma[0]), float(sigma[1]))
        return KnownPart(float(x[X]), float(x[Y]), size, self.height.height_mm, refine=self.height.wants_refine,
                         shades=self._lent_shades())

    def _lent_shades(self) -> FaceShades | None:
        return None if self.shades is None else self.shades.lent()

    def _normalise(self) -> None:
        """Keep the angle in (-90, 90] and the length the longer side (180 deg symmetry)."""
        x = self.kf.x
        if x[WIDTH, 0] > x[LENGTH, 0]:
            order = list(range(8))
            order[LENGTH], order[WIDTH] = WIDTH, LENGTH
            self.kf.x = x[order]
            self.kf.P = self.kf.P[np.ix_(order, order)]
            self.kf.x[ANGLE, 0] += 90.0
        self.kf.x[ANGLE, 0] = wrap_angle_deg(float(self.kf.x[ANGLE, 0]))

    def output(self, measured: Measurement | None) -> TrackedObject:
        x = self.kf.x[:, 0]
        corners = rectangle_corners(x[X], x[Y], x[ANGLE], x[LENGTH], x[WIDTH])
        height, converged = 0.0, True
        if self.height is not None:
            height, converged = self.height.height_mm, self.height.converged
        return TrackedObject(
            self.id, float(x[X]), float(x[Y]), float(x[ANGLE]), float(x[LENGTH]), float(x[WIDTH]),
            corners, float(x[VX]), float(x[VY]), measured is not None, measured, height_mm=height,
            height_converged=converged, age_frames=self.age_frames, pickable=self.pickable,
        )

    def ended(self, t_ns: int, cfg: TrackConfig) -> bool:
        """No blob for too long: time for an established track moving with the belt (a part an arm passes
        over), frames for any other."""
        speed = math.hypot(float(self.kf.x[VX, 0]), float(self.kf.x[VY, 0]))
        if not self.settled(cfg) or speed < cfg.coast_min_speed_mm_s:
            return self.missed > cfg.max_missed_frames
        return t_ns - self.seen_ns > cfg.max_coast_s * 1e9


def _filter_from(m: Measurement, cfg: TrackConfig) -> KalmanFilter:
    """A filter started at measurement ``m``: its size as sure as its view made it (see BoxFit)."""
    r = m.rect
    kf = make_filter(np.array([r.x_mm, r.y_mm, r.angle_deg, r.length_mm, r.width_mm]), cfg)
    if m.size_cov_mm2 is not None:
        size = [LENGTH, WIDTH]
        kf.P[np.ix_(size, size)] = _size_noise(m, cfg)
    return kf


def _size_noise(m: Measurement, cfg: TrackConfig) -> np.ndarray:
    """A box's size uncertainty (length, width; mm^2): its view's, and no less than any measurement's."""
    return m.size_cov_mm2 + np.eye(2) * cfg.size_sigma_mm**2


class Tracker:
    """Greedy nearest-neighbour association of measurements to Kalman tracks."""

    def __init__(self, config: TrackConfig, in_view: Callable[[float, float], bool] | None = None,
                 height_vote_step_mm: float | None = None) -> None:
        """``height_vote_step_mm``: with --part-height auto, how far apart the views that vote on a part's
        height are (see HeightEstimate; None: heights given, or none)."""
        self.config = config
        self._vote_step_mm = height_vote_step_mm
        # Whether a belt point is inside the camera's view: a track predicted out of view ends.
        self._in_view = in_view or (lambda x, y: True)
        self.tracks: list[Track] = []
        self._next_id = 1

    def known(self, t_ns: int, offset_mm: tuple[float, float] = (0.0, 0.0)) -> list[KnownPart]:
        """The settled parts, predicted to ``t_ns``: what the measurement may lean on, in the world frame
        (the tracks' own moved by ``offset_mm``: see Track.known). With heights estimated, the young tracks
        still voting too, without their unsettled sizes: so that their views vote only when they count
        (a vote is a box fit at every height, and spends the frame's votes), and are posed at the height
        leading their vote between."""
        out = []
        for track in self.tracks:
            settled = track.settled(self.config) and not track.tentative
            voting = track.height is not None and track.height.voting
            if track.odd_size_since_ns is None and (settled or voting):
                track.predict(t_ns, self.config)
                known = track.known(self.config, offset_mm)
                out.append(known if settled else replace(known, size=None))
        return out

    def step(self, measurements: list[Measurement], t_ns: int) -> tuple[TrackedObject, ...]:
        cfg = self.config
        for track in self.tracks:
            track.predict(t_ns, cfg)
        merged = self._merged(measurements)
        owners = self._owners(merged, measurements, t_ns)
        # A blob one of its tracks owns: the others in it are that part's duplicates, ended here.
        duplicates = {ti for ti, mi in merged.items() if mi in owners and owners[mi] != ti}
        merged = {ti: mi for ti, mi in merged.items() if mi not in owners}
        pairs = []
        for ti, track in enumerate(self.tracks):
            if ti in merged or ti in duplicates or ti in owners.values():
                continue
            for mi, m in enumerate(measurements):
                if mi in merged.values() or mi in owners:
                    continue
                d = math.dist(track.position, (m.rect.x_mm, m.rect.y_mm))
                # A clipped blob's centre is off the part's: allow for half the part.
                # A centroid inside the predicted part (half its width) is that part whatever its size:
                # parts lie flat and apart, so no other part's centroid can be there.
                gate = max(cfg.gate_mm, float(track.kf.x[WIDTH, 0]) / 2)
                gate += float(track.kf.x[LENGTH, 0]) / 2 if m.clipped else 0.0
                if d <= gate:
                    pairs.append((d, ti, mi))
        pairs.sort()
        track_to_m = {ti: mi for mi, ti in owners.items()}
        used = set(owners)
        for _, ti, mi in pairs:
            if ti not in track_to_m and mi not in used:
                track_to_m[ti] = mi
                used.add(mi)
        used.update(merged.values())
        out, alive = [], []
        for ti, track in enumerate(self.tracks):
            if ti in duplicates:
                continue
            m = measurements[track_to_m[ti]] if ti in track_to_m else None
            if ti in merged:
                # One blob holds this part and another: neither can be measured, nor picked.
                m = measurements[merged[ti]]
                track.pickable = False
                if track.odd_size_since_ns is None:
                    track.odd_size_since_ns = t_ns
                    track.rewind(t_ns, cfg)
            elif m is not None and not m.clipped and track.settled(cfg):
                m = self._check_size(track, m, t_ns)
            elif m is not None and not m.clipped and track.size_jump(m, cfg):
                # A young track takes the size it is measured at now (its first blob was a sliver).
                track.restart(m, cfg)
            if m is None:
                track.missed += 1
                x, y = track.position
                if track.ended(t_ns, cfg) or not self._in_view(float(x), float(y)):
                    continue
            else:
                track.missed = 0
                track.seen_ns = t_ns
            if m is not None and not m.clipped and ti not in merged and track.odd_size_since_ns is None:
                track.update(m, cfg)
                track.hits += 1
                track.age_frames = 0
                out.append(track.output(m))
            else:
                track.age_frames += 1
                out.append(track.output(None))
            alive.append(track)
        for mi, m in enumerate(measurements):
            if mi not in used and not m.clipped and not self._inside_known(m, alive, measurements):
                track = Track(self._next_id, m, t_ns, cfg, self._vote_step_mm)
                self._next_id += 1
                alive.append(track)
                out.append(track.output(m))
        self.tracks = alive
        shown = {t.id for t in alive if not t.tentative or t.settled(cfg)}
        for t in alive:
            t.tentative = t.id not in shown
        return tuple(sorted((o for o in out if o.id in shown), key=lambda o: o.id))

    def _check_size(self, track: Track, m: Measurement, t_ns: int) -> Measurement:
        """A blob of another size than its established part is not a measurement of it: the part is partly
        hidden (an arm, a bracket; smaller) or another part has joined it (larger: then it is not pickable).
        A size kept for max_coast_s is the part's own after all (its first blobs were wrong)."""
        cfg = self.config
        # A blob aside is as a part partly hidden (a piece: smaller) or joined by another (larger).
        jump = track.size_jump(m, cfg) or track.aside(m, cfg)
        if not jump:
            track.odd_size_since_ns = None
            return m
        if track.odd_size_since_ns is None:
            track.odd_size_since_ns = t_ns
            track.rewind(t_ns, cfg)
        if t_ns - track.odd_size_since_ns > cfg.max_coast_s * 1e9:
            track.restart(m, cfg)
            return m
        if jump > 0:
            track.pickable = False
        return m

    def _merged(self, measurements: list[Measurement]) -> dict[int, int]:
        """Settled tracks whose predicted centres lie inside one blob with another's: track -> blob."""
        out: dict[int, int] = {}
        for mi, m in enumerate(measurements):
            if m.clipped or m.piece:
                continue
            outline = m.rect.corners().astype(np.float32)
            inside = [ti for ti, t in enumerate(self.tracks) if t.settled(self.config)
                      and cv2.pointPolygonTest(outline, tuple(map(float, t.position)), False) >= 0]
            if len(inside) > 1:
                out.update(dict.fromkeys(inside, mi))
        return out

    def _owners(self, merged: dict[int, int], measurements: list[Measurement], t_ns: int) -> dict[int, int]:
        """Blobs holding several settled tracks (see _merged) that one of them has matched at its own size,
        where it is predicted, for longer than max_coast_s: blob -> that track. The others are its
        duplicates: a part whose blob split for a moment (a belt's stop and start, motion blur), a piece
        starting a track of its own, and joined again. Two parts that touch make a blob larger than either,
        and stay merged (a real foil pouch, blurred: both tracks coasted inside its blob for 80 frames,
        neither measured)."""
        cfg = self.config
        out: dict[int, int] = {}
        for mi in set(merged.values()):
            m = measurements[mi]
            own = [ti for ti, blob in merged.items() if blob == mi
                   and self.tracks[ti].odd_size_since_ns is not None
                   and t_ns - self.tracks[ti].odd_size_since_ns > cfg.max_coast_s * 1e9
                   and not self.tracks[ti].size_jump(m, cfg) and not self.tracks[ti].aside(m, cfg)]
            if own:
                out[mi] = max(own, key=lambda ti: (self.tracks[ti].hits, -self.tracks[ti].id))
        return out

    def _inside_known(self, m: Measurement, tracks: list[Track], measurements: list[Measurement]) -> bool:
        """Whether the blob is a piece of a known part rather than a new one: its centre lies within a
        tracked part's predicted rectangle, or next to a part running out of view (within the gate of a
        clipped blob's rectangle). Parts do not stand on each other's centres, so such a blob is a
        fragment (a part half under a bracket), or the rest of a part tipping off the belt's end."""
        for track in tracks:
            x = track.kf.x[:, 0]
            outline = rectangle_corners(x[X], x[Y], x[ANGLE], x[LENGTH], x[WIDTH]).astype(np.float32)
            if cv2.pointPolygonTest(outline, (m.rect.x_mm, m.rect.y_mm), False) >= 0:
                return True
        for other in measurements:
            if other.clipped:
                r = other.rect
                corners = rectangle_corners(r.x_mm, r.y_mm, r.angle_deg, r.length_mm, r.width_mm).astype(np.float32)
                if cv2.pointPolygonTest(corners, (m.rect.x_mm, m.rect.y_mm), True) >= -self.config.gate_mm:
                    return True
        return False
