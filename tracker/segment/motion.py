"""Belt motion from the images: the shift of the belt between consecutive frames.

Phase correlation of two frames finds their dominant translation: inside the belt's region of
interest that is the belt (its texture, streaks and the parts riding on it all move together).
Duplicate frames and stops read as zero.

The correlation surface's highest sample gives the whole pixels; the fraction comes from the same
surface evaluated between the samples (a DFT of the cross spectrum at the points asked for, after
Guizar-Sicairos et al., "Efficient subpixel image registration algorithms", 2008). The centroid of
the samples around the peak, what ``cv2.phaseCorrelate`` returns, is pulled towards whole pixels: by
up to 0.4 px of the averaged-down patch (a belt creeping 1 px per frame read 0.6), and by different
amounts in different OpenCV versions.
"""

from __future__ import annotations

import cv2
import numpy as np

# The correlated patch is at most this many pixels on its long side (averaged down first):
# the cost stays bounded on any camera, and a belt's travel per frame stays measurable.
_PATCH_PX = 256
# A shift whose correlation peak is weaker than this is no measurement (a featureless or
# changing view): the belt is taken to keep its last shift.
_MIN_RESPONSE = 0.05
# Frames differing by less than this (mean |diff|, grey levels) repeat each other (a frame-rate
# conversion): the belt did not stop, the frame is just not new; its last shift is kept.
DUPLICATE_LEVEL = 0.3
# The surface between samples is evaluated from frequencies up to this (cycles per pixel, along
# each axis): an averaged-down belt's texture is there, the higher ones are mostly noise.
_BAND = 0.25
# The fraction of a pixel is found to 1 / this (of the averaged-down patch).
_UPSAMPLE = 40


class BeltMotion:
    """Shift of the belt (image pixels, dx, dy) between each frame and the one before it."""

    def __init__(self, roi_mask: np.ndarray) -> None:
        ys, xs = np.nonzero(roi_mask)
        x0, x1, y0, y1 = xs.min(), xs.max() + 1, ys.min(), ys.max() + 1
        self._box = (slice(int(y0), int(y1)), slice(int(x0), int(x1)))
        scale = min(1.0, _PATCH_PX / max(x1 - x0, y1 - y0))
        # Each side of a length whose FFT is fast (a prime one takes several times as long), and so each
        # its own scale.
        self._size = tuple(_smooth_at_most(max(8, round(n * scale))) for n in (x1 - x0, y1 - y0))
        self._scales = (self._size[0] / (x1 - x0), self._size[1] / (y1 - y0))
        self._window = cv2.createHanningWindow(self._size, cv2.CV_64F)
        self._prev: np.ndarray | None = None
        self._prev_spectrum: np.ndarray | None = None
        self.shift_px = (0.0, 0.0)
        # The last frame repeated the one before it.
        self.duplicate = False

    def __call__(self, frame: np.ndarray) -> tuple[float, float]:
        patch = frame[self._box]
        if self._size != (patch.shape[1], patch.shape[0]):
            patch = cv2.resize(patch, self._size, interpolation=cv2.INTER_AREA)
        patch = patch.astype(np.float64)  # numpy's FFT is fastest in double precision
        prev, self._prev = self._prev, patch
        self.duplicate = prev is not None and cv2.norm(patch, prev, cv2.NORM_L1) / patch.size < DUPLICATE_LEVEL
        if prev is None or self.duplicate:
            self._prev_spectrum = None  # that of another patch than the one now kept
            return self.shift_px
        spectrum = _spectrum(patch, self._window)
        prev_spectrum = self._prev_spectrum if self._prev_spectrum is not None else _spectrum(prev, self._window)
        self._prev_spectrum = spectrum  # the next frame's previous
        found = phase_shift(prev_spectrum, spectrum, patch.shape)
        if found is not None:
            self.shift_px = (found[0] / self._scales[0], found[1] / self._scales[1])
        return self.shift_px


def _spectrum(patch: np.ndarray, window: np.ndarray) -> np.ndarray:
    """The patch's half spectrum, its mean removed and Hann-windowed (``window``, of its shape: its
    borders, cut off by the crop, would otherwise correlate with themselves at no shift, and so would
    its mean through the window)."""
    return np.fft.rfft2((patch - patch.mean()) * window)


def phase_shift(before: np.ndarray, after: np.ndarray, shape: tuple[int, int]) -> tuple[float, float] | None:
    """How far the content of the patch whose spectrum is ``after`` moved from that of ``before`` (px, dx
    and dy; both spectra of patches of ``shape``, see _spectrum); None when the correlation peak is
    weaker than a shift needs (see _MIN_RESPONSE)."""
    h, w = shape
    cross = after * np.conj(before)
    magnitude = np.abs(cross)
    if not magnitude.max() > 0:
        return None  # a featureless view
    normalised = cross / np.maximum(magnitude, 1e-12 * magnitude.max())  # phase only
    surface = np.fft.irfft2(normalised, s=(h, w))
    py, px = np.unravel_index(int(np.argmax(surface)), surface.shape)
    # The peak's strength: the normalised correlation around it (about 1 for a pure translation).
    response = float(surface[np.ix_([(py + j) % h for j in (-1, 0, 1)], [(px + i) % w for i in (-1, 0, 1)])].sum())
    if response < _MIN_RESPONSE:
        return None
    fy, fx = np.fft.fftfreq(h), np.fft.rfftfreq(w)
    rows, cols = np.abs(fy) <= _BAND, fx <= _BAND
    # The half spectrum stands for both halves (a real image's is symmetric).
    band = normalised[np.ix_(rows, cols)] * np.where(fx[cols] > 0, 2.0, 1.0)
    # The surface between samples: first at quarter pixels around the highest sample, then finely
    # around the best of those.
    centre = np.array([px - w if px > w // 2 else px, py - h if py > h // 2 else py], float)
    for span, step in ((0.75, 0.25), (0.25, 1.0 / _UPSAMPLE)):
        offsets = np.arange(-span, span + step / 2, step)
        ys, xs = centre[1] + offsets, centre[0] + offsets
        # einsum, not @: BLAS would start its threads for these small products (a millisecond a frame,
        # and the segmentation's own threads kept waiting).
        along_y = np.einsum("yr,rc->yc", np.exp(2j * np.pi * np.outer(ys, fy[rows])), band)
        between = np.einsum("yc,cx->yx", along_y, np.exp(2j * np.pi * np.outer(fx[cols], xs))).real
        j, i = np.unravel_index(int(np.argmax(between)), between.shape)
        centre = np.array([xs[i], ys[j]])
    return float(centre[0]), float(centre[1])


def _smooth_at_most(n: int) -> int:
    """The largest number not above ``n`` with no prime factor above 5."""
    while True:
        m = n
        for p in (2, 3, 5):
            while m % p == 0:
                m //= p
        if m == 1:
            return n
        n -= 1
