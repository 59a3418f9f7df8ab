"""Reading calibration images: grey, all of one size, with one clear line for each bad file."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from tracker.errors import BadInput


def read_grey(path: str | Path) -> np.ndarray:
    path = Path(path)
    if not path.is_file():
        raise BadInput(f"{path}: image file not found")
    image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if image is None or image.size == 0:
        raise BadInput(f"{path}: cannot read as an image (expected a PNG, JPEG, BMP or TIFF file)")
    return image


def read_all_same_size(paths: list[str]) -> tuple[list[np.ndarray], tuple[int, int]]:
    """Every image, grey; BadInput naming the first file whose size differs from the first image's."""
    images = [read_grey(p) for p in paths]
    h0, w0 = images[0].shape[:2]
    for path, image in zip(paths, images, strict=True):
        h, w = image.shape[:2]
        if (w, h) != (w0, h0):
            raise BadInput(f"{path}: image is {w}x{h}, expected {w0}x{h0} like {paths[0]} (all views from one camera)")
    return images, (w0, h0)
