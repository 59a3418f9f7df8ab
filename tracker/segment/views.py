"""Views of an image computed only for the slices asked for: the working image seen at full
resolution, and a frame seen through a slight blur."""

from __future__ import annotations

import cv2
import numpy as np


class UpsampledView:
    """A small image seen at full resolution (bilinear, as ``cv2.resize`` would scale it up),
    computed only for the slices asked for: ``view[y0:y1, x0:x1]`` is a float32 array."""

    def __init__(self, small: np.ndarray, size: tuple[int, int], scale: float) -> None:
        self._small = small
        self._scale = scale
        self.shape = (size[1], size[0])

    def __getitem__(self, key: tuple[slice, slice]) -> np.ndarray:
        rows, cols = key
        y0, y1, _ = rows.indices(self.shape[0])
        x0, x1, _ = cols.indices(self.shape[1])
        s = self._scale
        # Full pixel centre (x + 0.5) sits at (x + 0.5) * s - 0.5 in the small image.
        m = np.float32([[s, 0, (x0 + 0.5) * s - 0.5], [0, s, (y0 + 0.5) * s - 0.5]])
        return cv2.warpAffine(self._small, m, (max(0, x1 - x0), max(0, y1 - y0)),
                              flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP, borderMode=cv2.BORDER_REPLICATE)

    def full(self) -> np.ndarray:
        return self[0 : self.shape[0], 0 : self.shape[1]]


class SmoothedView:
    """A frame seen through a slight blur (8-bit), computed only for the slices asked for: on a
    textured belt, the measurement's grey-level edges then average the texture over neighbouring
    rows as well as along each row. The blur is symmetric, so an edge stays where it is."""

    def __init__(self, frame: np.ndarray, sigma_px: float) -> None:
        self._frame = frame
        self._sigma = sigma_px
        self._margin = int(np.ceil(3 * sigma_px))
        self.shape = frame.shape

    def __getitem__(self, key: tuple[slice, slice]) -> np.ndarray:
        rows, cols = key
        y0, y1, _ = rows.indices(self.shape[0])
        x0, x1, _ = cols.indices(self.shape[1])
        m = self._margin
        a0, b0 = max(0, y0 - m), max(0, x0 - m)
        crop = self._frame[a0 : min(self.shape[0], y1 + m), b0 : min(self.shape[1], x1 + m)]
        blurred = cv2.GaussianBlur(crop, (0, 0), self._sigma, borderType=cv2.BORDER_REPLICATE)
        return blurred[y0 - a0 : y1 - a0, x0 - b0 : x1 - b0]
