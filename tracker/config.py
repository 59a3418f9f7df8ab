"""Every tunable of the vision pipeline, typed, with its default, in one place.

A recording stores ``TrackerConfig.to_dict()`` so a replay rebuilds exactly the
same pipeline with ``TrackerConfig.from_dict``.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields

from tracker.errors import BadInput

SEGMENT_MODELS = ("auto", "reference", "textured")


@dataclass(frozen=True)
class SegmentConfig:
    # |frame - background| above this (grey levels) is foreground.
    diff_threshold: int = 30
    # ... and above this where it joins foreground on the same side of the belt's level, 2 px wide or more
    # (hysteresis): a box's side face in shadow can differ from the belt by less than diff_threshold and
    # still be the part's (its silhouette's outer edge). 0 (or diff_threshold and above): none joins.
    faint_threshold: int = 12
    # |frame - previous frame| above this is motion; background learns only where still.
    motion_threshold: int = 12
    # Learning rate of the empty-belt reference where nothing moves.
    background_rate: float = 0.1
    # Each pixel of the reference learns every N frames (one 1/N stripe of rows per frame).
    background_every: int = 4
    # A foreground blob with no motion in it for this many frames joins the background
    # (a parked part, or a ghost left where a part sat when the reference was taken).
    absorb_after_frames: int = 90
    # Start-up (plain belt model): where the first frame is unlike the belt's level it may hold parts,
    # and the belt's level stands in for it; for at most this many frames (then what is left is taken
    # as the frame shows it), and unless more than this fraction of the region of interest is unlike
    # the belt (the view is then not mostly belt: the first frame is taken as it is).
    startup_frames: int = 30
    startup_max_fraction: float = 0.3
    # Side of the square opening kernel that removes noise speckles from the mask.
    open_kernel_px: int = 3
    # Belt model: "reference" (a per-pixel image of the empty belt: exact on plain belts whose
    # look does not move), "textured" (real belts whose texture, streaks and seams move with
    # the parts: texture-suppressed levels against per-pixel statistics of the passing belt), or
    # "auto": "reference" until the belt's own look is seen to move with it, then "textured" for
    # good (segment/look.py): the region of interest cut into auto_tiles tiles along its longer
    # side, a tile changing where about auto_tile_changed of its pixels or more differ from the last
    # frame by more than motion_threshold (3 x 3 means, the region's mean step taken out), the look
    # moving once the median share of tiles changing over auto_frames new frames reaches
    # auto_moving_share (real belts 0.2-0.8, rendered plain belts with up to five parts at most
    # 0.17). Until auto_frames new frames are watched, and while the last changed that many tiles,
    # no part is pickable.
    model: str = "auto"
    auto_tiles: int = 16
    auto_tile_changed: float = 0.01
    auto_frames: int = 9
    auto_moving_share: float = 0.3
    # Region of interest, set once: the belt area as an image polygon [[x, y], ...] (pixels) or a
    # belt polygon (mm, world frame); outside it nothing is a part. Empty: the whole image.
    roi_px: tuple = ()
    roi_mm: tuple = ()
    # Foreground covering more than this fraction of the region of interest is not parts but a
    # changed scene (light switched on, camera bumped, wrong settings): fault 5, nothing tracked.
    scene_fault_fraction: float = 0.5
    # At most this many blobs (the largest) are measured per frame: work per frame stays bounded.
    max_blobs: int = 24
    # Textured model: frames are averaged down to about this many pixels on their long side, which
    # averages out a belt's fine texture (diamonds, fibres, compression noise) while parts, tens of
    # pixels across, keep their level.
    textured_work_px: int = 240
    # Textured model: foreground where the smoothed level differs from the belt's by more than this
    # (grey levels) and by more than textured_sigmas standard deviations of the passing belt there.
    textured_threshold: float = 16.0
    textured_sigmas: float = 4.0
    # Textured model: a part differs from the belt by at least this much (grey levels, the 90th
    # percentile of its smoothed contrast); fainter blobs are stains, sheets or light on the belt.
    # Parts are specified from 30 levels of contrast up.
    min_part_contrast: float = 28.0
    # Textured model: learning rate of the belt's per-pixel mean and variance per pixel of belt
    # travel (a stopped belt or a duplicate frame brings no new belt, so it teaches nothing).
    textured_rate: float = 0.04
    # Textured model: the narrowest part's width on the belt (mm); foreground thinner than this is a
    # streak, seam or mark across the belt. 0: only what the working image cannot resolve (~2 % of
    # the frame's long side) is thin.
    min_part_mm: float = 0.0

    def __post_init__(self) -> None:
        _positive(self, "diff_threshold", "motion_threshold", "background_every", "startup_frames",
                  "absorb_after_frames", "open_kernel_px", "max_blobs", "textured_work_px",
                  "textured_threshold", "textured_sigmas", "min_part_contrast", "auto_tiles", "auto_frames")
        if self.auto_tiles > 64:
            raise BadInput(f"segment.auto_tiles: expected at most 64 tiles along the region, got {self.auto_tiles}")
        for name in ("auto_tile_changed", "auto_moving_share"):
            if not 0 < getattr(self, name) < 1:
                raise BadInput(f"segment.{name}: expected a share 0 < s < 1, got {getattr(self, name)}")
        if self.model not in SEGMENT_MODELS:
            raise BadInput(f"segment.model: expected one of {list(SEGMENT_MODELS)}, got {self.model!r}")
        if self.faint_threshold < 0:
            raise BadInput(f"segment.faint_threshold: expected >= 0 (0: none joins), got {self.faint_threshold}")
        if self.roi_px and self.roi_mm:
            raise BadInput("segment: expected roi_px or roi_mm, not both")
        for name in ("roi_px", "roi_mm"):
            _check_polygon(f"segment.{name}", getattr(self, name))
            # Tuples: the settings stay hashable and compare equal however they were given.
            object.__setattr__(self, name, tuple(tuple(float(v) for v in p) for p in getattr(self, name)))
        if not 0 <= self.startup_max_fraction <= 1:
            raise BadInput(f"segment.startup_max_fraction: expected 0 <= f <= 1, got {self.startup_max_fraction}")
        if not 0 < self.scene_fault_fraction <= 1:
            raise BadInput(f"segment.scene_fault_fraction: expected 0 < f <= 1, got {self.scene_fault_fraction}")
        if self.min_part_mm < 0:
            raise BadInput(f"segment.min_part_mm: expected >= 0, got {self.min_part_mm}")
        if not 0 < self.textured_rate <= 1:
            raise BadInput(f"segment.textured_rate: expected 0 < rate <= 1, got {self.textured_rate}")
        if self.absorb_after_frames > 255 * self.background_every:
            raise BadInput(f"absorb_after_frames: expected <= 255 * background_every "
                           f"({255 * self.background_every}), got {self.absorb_after_frames}")
        if not 0 < self.background_rate <= 1:
            raise BadInput(f"background_rate: expected 0 < rate <= 1, got {self.background_rate}")


@dataclass(frozen=True)
class MeasureConfig:
    # Blobs smaller than this on the belt are not parts.
    min_area_mm2: float = 300.0
    # Outlines are measured on the plane this high above the belt (0 for flat parts).
    part_height_mm: float = 0.0
    # A blob within this many pixels of the image border is clipped: not a measurement.
    border_margin_px: int = 2
    # Locate edges from grey levels (sub-pixel) instead of the binary mask's staircase.
    subpixel: bool = True
    # Pixels around a blob's bounding box that are examined for its edges.
    roi_margin_px: int = 4
    # Points within this many pixels of a fitted side (and away from corners) refine it.
    side_band_px: float = 1.5
    # Minimum |part - belt| contrast (grey levels) for a sub-pixel measurement; on the plain belt model
    # no more than segment.faint_threshold (a face it joins to a part is read).
    min_contrast: float = 20.0
    # On the plain belt model, a bright part's edge whose window ends (the darker of its two outermost
    # pixels) on belt darker than the belt's model by more than this (grey levels) ends in the part's
    # shadow: it is read against the belt as dark as it is there (see measure._in_shadow).
    shadow_min_levels: float = 12.0
    # A box's edges are read against the face next to each (one pixel): windows where the belt comes
    # within min_contrast of it are left out, up to this fraction of those on one side of the blob (its
    # left edges along rows, say: there a part's side holds a quarter or more of them unless it is
    # longer than 3:1 and turned near 45 deg; beyond, a side may be missing, and the blob's edges are
    # not read from levels).
    max_unreadable_fraction: float = 0.15
    # Estimate each part's height from how its silhouette changes as it crosses the view (boxes of
    # several heights fitted to views along its path, the height whose sizes agree kept, then refined;
    # see tracker/height.py): --part-height auto, the default (contract section 3). A height given
    # (part_height_mm > 0) is not estimated; false with part_height_mm 0: every part flat.
    estimate_height: bool = True
    # Heights (mm) a part's vote tries. One view tells only which of these its edges fit best, and its
    # pose until the next vote is that height's: a part 10 mm from every height tried (30 mm, with 20
    # and 40) led at the wrong one, even flat, for several frames (bench/heights_random.py --any-height:
    # 26 of 60 scenes met issue 10's bounds with 0, 5, 10, 20, 40, 60; 32 with 30 and 15 added; 42 of
    # 60 with 50 too, 38 without: parts of 40-60 mm were posed at 40 or 60 until their vote decided,
    # 1-5 mm off). A thin part's boxes fit a view well only within a millimetre or so of its height,
    # worse than flat farther off: a 7.3 mm box at 20 deg fitted 0.059 px RMS at 7, 0.071 at 8, 0.070
    # at 5 and 6, 0.069 flat, and without 7.5 its vote found it flat (46 of 60 then, 49 with 7.5).
    # Below 5 nothing is tried: a flat part's boxes of 1-3 mm explain its edges a little better than
    # flat (their sliver shades take up the model's own error). Each costs a box fit in each of a
    # part's vote views.
    height_starts_mm: tuple = (0.0, 5.0, 7.5, 10.0, 15.0, 20.0, 30.0, 40.0, 50.0, 60.0)
    # At most this many parts vote in one frame (a vote is a box fit per height); the others wait for
    # the next frame, fitted at their leading height meanwhile.
    height_votes_per_frame: int = 1
    # With a part height: a box outline fitting its edge points worse than this (px RMS) means
    # the part is no box (a cylinder lying down, a bag); its top-face rectangle is kept instead.
    box_max_rms_px: float = 1.0
    # The camera's blur of an edge (a Gaussian's sigma, px: optics and focus; 0 for a sharp image).
    # A box's thin side face is a blurred mix in the pixels next to its edge, and the box fit
    # models that mix: with 1 px of blur left out, 10-20 mm boxes are off by 0.2-0.4 mm.
    edge_blur_px: float = 0.0
    # On a textured belt (its model smooths frames, see pipeline) a part's edges are read through that
    # smoothing only where the belt's texture around it is strong against the part: its pixels' median
    # deviation from the belt model over more than this fraction of the part's contrast. The smoothing
    # averages a knurl out of a faint part's edges (a part 30 levels off the belt, 0.15 here: 0.07 mm
    # centroid mean with it, 0.14 without), but spreads a box's side faces, the slivers its height is
    # told by: the tests' 20 mm box on a knurled belt under a codec (0.026 here), auto, converged after
    # 72-90 % of its crossing and 0.7-2.4 mm off on six seeds through the smoothing, after 15-21 % and
    # 0.4-0.6 mm off without; 90 levels above that belt (0.037), after 25-96 % through it, 18-33 %
    # without; 60 levels (0.055), with its height given, 0.36-0.43 mm centroid mean through it, 0.48-0.54
    # without (with auto, neither converges there).
    smooth_texture_ratio: float = 0.05
    # At most this many of a box's edge windows are fitted (evenly thinned beyond): the fit's cost
    # grows with them (bench/heights.py), while beyond a couple of hundred the pose hardly improves.
    box_max_windows: int = 240
    # A box's coverage sums scatter by about this much (px, 1 sigma): it weighs a size known from a
    # track's other views against the sums of one view, where a thin side face leaves the size open.
    sum_sigma_px: float = 0.1
    # The box model's own error on the sums a view reads its height from (px): a sub-pixel error that
    # does not average out over an edge's windows (a sensor's or a renderer's sampling of a sliver a
    # fifth of a pixel wide; the renderer's 8x8 samples err by 0.01-0.03 of a pixel's area on an edge).
    # A view tells its height no surer than such an error on every window, each the way that moves the
    # height most, allows (boxfit.view_information): near the middle of the view a thin part's height
    # rests on slivers whose windows move it 20-50 mm per pixel, and its views claimed it to 0.2 mm
    # where they read it 1-3 mm off, alike (bench/heights_random.py scene 48, a 5 mm box straight
    # down: 0.65 mm off once converged; 0.37 now). Over 1209 views of 48 random scenes, with 0.02 the
    # views' errors over the uncertainty they claim have a median of 0.61 (a normal's: 0.67; without,
    # 1.55, and one view in four beyond 3).
    model_sigma_px: float = 0.02
    # A part's track learns its side shades from its views (with --part-height auto those of its boxes
    # at the height it is estimated or voted to have, see Track._learn_shades) and lends them to its
    # fits where a side face is a sliver (tracker/shades.py): one view of a sliver settles its shade
    # wherever its fit starts, and its height comes out off (the tests' 10 mm box at 10 deg: 0.18 mm
    # once converged without, 0.07 with); with the height given, its pose (the same box straight down:
    # centroid 0.042 mm mean without, 0.014 with).
    learn_shades: bool = True
    # --part-height auto: a vote's view whose box of a height explains it only with a side face as
    # bright as the top (or darker than the belt's level allows) counts against that height as if its
    # sizes disagreed as much as a view's can (tracker/height.py), from a sharp image only. Off where
    # lamps light the parts' sides brighter than their tops: there it would count against the part's
    # own height. (The track's learnt shades, measure.learn_shades, do not depend on it.)
    vote_on_shades: bool = True
    # Parts whose sides differ by less than this (mm) are near square: which side is the length is
    # not told apart, so no known size is lent to their fit.
    square_mm: float = 1.0
    # Touching parts. A box's silhouette is convex: a notch this deep (px) in a blob's outline is
    # where two parts meet (a single part's pixel staircase and blur leave notches of about 1 px).
    touch_min_notch_px: float = 3.0

    def __post_init__(self) -> None:
        _positive(self, "min_area_mm2", "roi_margin_px", "side_band_px", "min_contrast", "shadow_min_levels",
                  "box_max_rms_px", "touch_min_notch_px", "sum_sigma_px", "square_mm", "box_max_windows",
                  "height_votes_per_frame")
        if self.smooth_texture_ratio < 0:
            raise BadInput(f"measure.smooth_texture_ratio: expected >= 0, got {self.smooth_texture_ratio}")
        if self.model_sigma_px < 0:
            raise BadInput(f"measure.model_sigma_px: expected >= 0, got {self.model_sigma_px}")
        if self.part_height_mm < 0:
            raise BadInput(f"part_height_mm: expected >= 0, got {self.part_height_mm}")
        if self.part_height_mm > 0:
            object.__setattr__(self, "estimate_height", False)  # a height given is not estimated
        if not 0 <= self.max_unreadable_fraction < 1:
            raise BadInput(f"measure.max_unreadable_fraction: expected 0 <= f < 1, got {self.max_unreadable_fraction}")
        if not 0 <= self.edge_blur_px <= 5:
            raise BadInput(f"measure.edge_blur_px: expected a blur from 0 to 5 px, got {self.edge_blur_px}")
        try:
            # JSON gives a list; keep the frozen settings hashable and equal however given.
            starts = tuple(float(h) for h in self.height_starts_mm)
        except (TypeError, ValueError):
            raise BadInput(f"measure.height_starts_mm: expected a list of heights in mm, "
                           f"got {self.height_starts_mm!r}") from None
        if not starts or not all(0 <= h < 5000 for h in starts):
            raise BadInput(f"measure.height_starts_mm: expected heights from 0 to 5000 mm, got {starts!r}")
        if len(set(starts)) < 2:
            raise BadInput(f"measure.height_starts_mm: expected at least two heights to vote on, got {starts!r}")
        object.__setattr__(self, "height_starts_mm", starts)


@dataclass(frozen=True)
class TrackConfig:
    # Measurement noise (1 sigma) of centroid, angle and side lengths.
    position_sigma_mm: float = 0.08
    angle_sigma_deg: float = 0.1
    size_sigma_mm: float = 0.1
    # The least uncertainty (1 sigma, mm) a track's size is lent to a box's fit with (see measure.sum_sigma_px).
    known_size_sigma_mm: float = 0.02
    # With measure.learn_shades, a box's side shades as its track's views tell them together
    # (tracker/shades.py): lent to each fit no surer than known_shade_sigma (1 sigma, a fraction of
    # the top's contrast; weighed as the size is, see measure.sum_sigma_px); a view counts no surer
    # than shade_view_min_sigma, and not at all where it tells a shade worse than
    # shade_view_max_sigma (a sliver too narrow to show it); what views told fades over
    # shade_memory_views views (a face turning towards a lamp changes shade). Each side face has its
    # own shade, within opposite_shade_sigma of the face opposite it (a lamp to one side lights them
    # unalike; a face no view has shown yet starts from the other's).
    known_shade_sigma: float = 0.03
    shade_view_min_sigma: float = 0.05
    shade_view_max_sigma: float = 0.15
    shade_memory_views: float = 100.0
    opposite_shade_sigma: float = 0.1
    # --part-height auto (tracker/height.py). The vote: views height_vote_step_mm apart along the part's
    # path, or on a view smaller than the renderer's default camera's (690 mm: the square root of the
    # belt area it sees) height_vote_step_fraction of its size (a part crossing a camera's view of 400
    # x 300 mm voted at 40 mm steps decided after 41 % of its crossing, at 20 mm after 19 %; larger
    # views keep 40 mm: at 0.058 of theirs, 47-58 mm, 2 of bench/heights_random.py's first 60 scenes
    # went from 9-12 % of their crossing to 40 %). Each is fitted at each height of
    # measure.height_starts_mm, their sizes expected to agree as well as each view decides them, and no
    # better than height_vote_size_sigma_mm (1 sigma); no view adds more than height_vote_view_cap to a
    # height's score, and how much worse a height explains the edges counts height_vote_cost_weight (a
    # box fit stopped short costs as much as a wrong height).
    height_vote_step_mm: float = 40.0
    height_vote_step_fraction: float = 0.058
    height_vote_size_sigma_mm: float = 0.1
    height_vote_view_cap: float = 25.0
    height_vote_cost_weight: float = 0.2
    # The best height wins once it leads by this margin (a chi-square) the heights tried that do not
    # bracket the vote's lead (flat: all others), over at least height_vote_min_views views, or after
    # height_vote_views views.
    height_vote_margin: float = 25.0
    height_vote_min_views: int = 3
    height_vote_views: int = 8
    # A flat part's thin boxes explain each of its views as well as flat (sides as dark as the belt, or
    # as bright as the top): no one view tells them apart. A box is no rival of a flat lead once the
    # vote's views, read together with the size they share, need a side shade this many sigmas beyond
    # those a side may have (see HeightEstimate._needs_other_sides; sharp images with
    # measure.vote_on_shades only: elsewhere no view reads its shades).
    height_vote_flat_shade_sigmas: float = 2.0
    # A part's height need not be one of measure.height_starts_mm: between the best height's neighbours
    # (halfway to each) the vote's sizes are interpolated at steps of this (mm), and the height where
    # they agree best leads (see HeightEstimate._between).
    height_vote_resolution_mm: float = 0.1
    # The refinement starts from the vote's size held this tightly (1 sigma, mm: the vote's boxes agree
    # on it, while one view's fit with the height free slides along its valley), its height within this
    # fraction of the span of the voted height's neighbours (1 sigma). No view counts surer than
    # view_height_sigma_mm (1 sigma) of its height, nor than view_size_sigma_mm of its size: a view's
    # size errs along its valley with its height, by 0.2-0.4 mm where its height errs by 0.5-1 (the
    # tests' 20 mm box at 10 deg; held to 0.1, one view that a young estimate disagreed with on its
    # length alone was left out, and the estimate settled 0.8 mm high). Views whose height rests on
    # slivers say how unsure they are themselves (measure.model_sigma_px); the floor was 0.5 before
    # they did. The view that decides the vote tells the track its side shades only if its box is
    # within view_height_sigma_mm of the height voted (with measure.learn_shades: the shades a box of
    # another height needs are another part's).
    start_shape_sigma_mm: float = 0.3
    start_height_span_fraction: float = 0.125
    view_height_sigma_mm: float = 0.3
    view_size_sigma_mm: float = 0.15
    # ... and on the textured belt model's coarse reference no surer than this: its views misread a
    # part's edges alike from frame to frame (the reference learnt at low resolution, a codec's blocks),
    # so what they tell together is less than their sum (bench/heights_random.py --textured, 60
    # scenes: at 0.3 about ten converged 0.5-1.3 mm off; at 0.5, 43 meet every bound, 40 before;
    # at 0.5 for every model the sharp sets lost 3-4 scenes each, late: docs/HISTORY.md).
    view_height_sigma_coarse_mm: float = 0.5
    # A view that tells its own height (its size marginalised out) less surely than this (1 sigma, mm)
    # adds nothing to the estimate: it shows hardly any side face (near the middle of the view, a thin
    # part), so it tells the height only from the part's apparent size, which an edge bias of a
    # twentieth of a pixel moves by a millimetre alike in every such view (the tests' 5 mm box at 10
    # deg: its views near the middle claimed 6-15 mm and pulled it 0.5 mm up). Whether it disagrees
    # with the estimate (view_gate_chi2) still counts: left out of that too, a wrong vote's estimate
    # was voted on again only near the middle of the view (the tests' 15 mm box at 10 deg, never
    # converged; counted, after 62 % of its crossing, 0.25 mm off). With the model's own error in what
    # a view claims (measure.model_sigma_px) such views say so themselves; 0.5 before, and 1 mm since
    # lets in views that tell a little, honestly (random scenes: 112 of 120 met every bound with 0.5).
    view_height_told_sigma_mm: float = 1.0
    # A view whose own shape disagrees with the estimate by more than this chi-square (3 degrees of
    # freedom) is left out; this many in a row, and the height is voted again. 16 (p = 0.001): at 25,
    # one view near the far edge claiming 7.5 +- 0.41 mm of a 10 mm box (chi-square 20) was let in and
    # moved it 0.47 mm (bench/heights_random.py --side-light scene 21; over the random sets 5 scenes
    # in, 2 out, docs/HISTORY.md).
    view_gate_chi2: float = 16.0
    view_gate_frames: int = 10
    # The height is converged once its 1-sigma uncertainty is below this (mm) over at least this many
    # views that agree with it (also those too unsure to add to it, view_height_told_sigma_mm); from
    # then on every height_refine_every-th view still tells its own (a second box fit).
    height_converged_sigma_mm: float = 0.3
    height_converged_views: int = 5
    height_refine_every: int = 3
    # A converged height stays converged until its uncertainty exceeds this (mm), or its views vote
    # again: later views' scatter widens it (see height.py's _spread), and on the tests' 10 mm box
    # straight down it went from 0.29 to 0.301 and back, flipping what the PLC reads twice.
    height_unconverged_sigma_mm: float = 0.5
    # A part its vote found flat is still checked as it crosses the view: a box's silhouette measured as
    # flat outgrows its footprint by its height times how much of its sides the camera sees there
    # (box.BoxCamera.silhouette_growth), a flat part's does not. Its views flat_check_step_mm or more
    # apart along its path (neighbouring frames of a slow belt err alike) are fitted as two sizes and
    # one height times that growth (see HeightEstimate._check_flat); once flat_check_views of them tell
    # a height of at least flat_check_height_mm, flat_check_z standard errors from none, flat is
    # refuted and its vote goes on without it. The standard error takes a size's noise as their
    # scatter about the fit, no less than flat_check_size_sigma_mm (the few views that first agree
    # claim more); views whose growths scatter by less than flat_check_growth_spread (RMS, mm per mm)
    # tell nothing: a part parked on a stopped belt is seen from one place, and its sizes' slow drift
    # (the texture under it, the track's own size the growth is computed for) read hundreds of mm.
    # Random scenes' 3 mm boxes, their sides under a pixel wide, were found flat in 12 of 24 (posed
    # 0.5-1.6 mm off): their sizes grew as 1.2-2.1 mm boxes' would (their sides read dimmer than their
    # top), 40-90 standard errors from none, after 4-10 views; flat parts' within 0.2 mm and 6
    # standard errors (plain, dark and textured belts through MPEG-4, 60 scenes). The floor, 1 mm,
    # leaves room below the thin boxes' 1.2 for a camera whose sizes err across the view by a tenth of
    # a mm (a lens calibrated less well than the renderer's), which would tell 0.3-0.5 mm.
    flat_check_views: int = 5
    flat_check_step_mm: float = 5.0
    flat_check_height_mm: float = 1.0
    flat_check_z: float = 10.0
    flat_check_size_sigma_mm: float = 0.02
    flat_check_growth_spread: float = 0.01
    # Process noise: how hard parts may accelerate / turn / change apparent size.
    accel_sigma_mm_s2: float = 2000.0
    angular_accel_sigma_deg_s2: float = 200.0
    size_rate_sigma_mm_s: float = 1.0
    # Prior uncertainty of a new track's velocity (it is unknown at birth).
    initial_velocity_sigma_mm_s: float = 1000.0
    initial_angular_rate_sigma_deg_s: float = 100.0
    # A measurement farther than this from a track's prediction starts a new track.
    gate_mm: float = 30.0
    # A young track (not yet established, see coast_min_hits) with no blob for this many frames ends:
    # a one-off false detection is not kept (and listed to the PLC) for long.
    max_missed_frames: int = 5
    # An established track with no blob keeps its id this long while it is predicted in view: an arm
    # passing over a part hides it for 0.3-0.5 s, and the part must come back under the same id.
    max_coast_s: float = 0.6
    # Measurements in a row at one size (see size_jump_mm) that make a track established: allowed to
    # coast for max_coast_s, and checked for size jumps and merges. A growing sliver (a part coming
    # into view, or leaving the ghost of its start position) is not established.
    coast_min_hits: int = 3
    # ... and it must move with the belt: a still blob that vanishes (the ghost of a part that was in
    # view at start, a part lifted off a stopped belt) ends after max_missed_frames like a young track.
    coast_min_speed_mm_s: float = 20.0
    # An established track's blob whose length or width differs from the part's by more than the larger
    # of these is not a measurement of it: the part is partly hidden (an arm, a bracket), or another
    # part touches it flush. It coasts meanwhile (up to max_coast_s, then the new size is taken).
    size_jump_mm: float = 4.0
    size_jump_fraction: float = 0.08
    # ... or by more than this many times the scatter of its own measured sizes (a running mean that
    # gives each new measurement this weight): on real footage sizes scatter by several mm.
    size_jump_sigmas: float = 4.0
    size_scatter_weight: float = 0.2
    # ... and the blobs of the frames just before were partly hidden already: the track goes back to its
    # state this many updates earlier (its velocity untouched by them) and coasts from there.
    rewind_frames: int = 3

    def __post_init__(self) -> None:
        _positive(self, *(f.name for f in fields(self)))
        if self.size_scatter_weight > 1:
            raise BadInput(f"track.size_scatter_weight: expected a weight in (0, 1], got {self.size_scatter_weight}")
        if self.shade_memory_views < 1:
            raise BadInput(f"track.shade_memory_views: expected at least 1 view, got {self.shade_memory_views}")
        if self.height_vote_resolution_mm < 0.01:
            raise BadInput(f"track.height_vote_resolution_mm: expected at least 0.01 mm (a finer step costs time "
                           f"and tells nothing more), got {self.height_vote_resolution_mm}")
        if self.flat_check_views < 3:
            raise BadInput(f"track.flat_check_views: expected at least 3 views (a growth and two sizes to "
                           f"fit), got {self.flat_check_views}")
        if self.height_unconverged_sigma_mm < self.height_converged_sigma_mm:
            raise BadInput(f"track.height_unconverged_sigma_mm: expected >= height_converged_sigma_mm "
                           f"({self.height_converged_sigma_mm}), got {self.height_unconverged_sigma_mm}")


@dataclass(frozen=True)
class TrackerConfig:
    segment: SegmentConfig = field(default_factory=SegmentConfig)
    measure: MeasureConfig = field(default_factory=MeasureConfig)
    track: TrackConfig = field(default_factory=TrackConfig)

    def to_dict(self) -> dict:
        """Plain JSON values (polygons as lists), so a round trip through a file compares equal."""
        return _json_ready(asdict(self))

    @classmethod
    def from_dict(cls, data: object) -> TrackerConfig:
        """Settings from parsed JSON; every value type-checked, so a bad file is one clear line."""
        if not isinstance(data, dict):
            raise BadInput(f"settings: expected a JSON object, got {type(data).__name__}")
        sections = {f.name: f for f in fields(cls)}
        unknown = set(data) - set(sections)
        if unknown:
            raise BadInput(f"settings: unknown sections {sorted(unknown)}; expected some of {sorted(sections)}")
        built = {}
        for name, f in sections.items():
            values = data.get(name, {})
            if not isinstance(values, dict):
                raise BadInput(f"{name}: expected an object of settings, got {type(values).__name__}")
            built[name] = _build(f.default_factory, name, values)
        return cls(**built)


def _build(kind: type, section: str, values: dict) -> object:
    defaults = kind()
    known = {f.name for f in fields(kind)}
    unknown = set(values) - known
    if unknown:
        raise BadInput(f"{section}: unknown settings {sorted(unknown)}; expected some of {sorted(known)}")
    for name, value in values.items():
        _check_type(f"{section}.{name}", value, getattr(defaults, name))
    return kind(**values)


def _check_type(name: str, value: object, default: object) -> None:
    """A setting must have its default's type: JSON's true is not 1, 2.5 is not an int, NaN is no number."""
    if isinstance(default, bool):
        ok, expected = isinstance(value, bool), "true or false"
    elif isinstance(default, int):
        ok, expected = isinstance(value, int) and not isinstance(value, bool), "an integer"
    elif isinstance(default, float):
        ok = isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)
        expected = "a finite number"
    elif isinstance(default, str):
        ok, expected = isinstance(value, str), "a string"
    elif isinstance(default, tuple | list):
        ok, expected = isinstance(value, list | tuple), "a list"
    else:
        return
    if not ok:
        raise BadInput(f"{name}: expected {expected}, got {value!r}")


def _positive(obj: object, *names: str) -> None:
    for name in names:
        value = getattr(obj, name)
        if not value > 0:
            raise BadInput(f"{type(obj).__name__}.{name}: expected > 0, got {value}")


def _check_polygon(name: str, points: object) -> None:
    if not points:
        return
    ok = (isinstance(points, list | tuple) and len(points) >= 3
          and all(isinstance(p, list | tuple) and len(p) == 2
                  and all(isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) for v in p)
                  for p in points))
    if not ok:
        raise BadInput(f"{name}: expected a polygon of >= 3 [x, y] number pairs, got {points!r}")


def _json_ready(value: object) -> object:
    if isinstance(value, dict):
        return {k: _json_ready(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_json_ready(v) for v in value]
    return value
