"""The calibration as a ROS ``camera_info`` YAML file (camera_calibration_parsers' format), so the
camera can be used in ROS tools, and intrinsics read back from one (a camera calibrated in ROS).
The OpenCV FileStorage file stays the one the tracker reads."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tracker.calibration import Calibration
from tracker.errors import BadInput


def _matrix(name: str, m: np.ndarray) -> list[str]:
    rows, cols = m.shape
    data = ", ".join(f"{float(v):.10g}" for v in m.reshape(-1))
    return [f"{name}:", f"  rows: {rows}", f"  cols: {cols}", f"  data: [{data}]"]


def camera_info_yaml(calib: Calibration, camera_name: str = "belt_camera") -> str:
    """``image_width``, ``image_height``, ``camera_name``, ``camera_matrix``, ``distortion_model``
    (plumb_bob for 5 coefficients, rational_polynomial for 8), ``distortion_coefficients``,
    ``rectification_matrix`` (identity: a monocular camera) and ``projection_matrix`` ([K | 0])."""
    d = calib.dist_coeffs.reshape(1, -1)
    model = "plumb_bob" if d.shape[1] <= 5 else "rational_polynomial"
    if d.shape[1] < 5:
        d = np.hstack([d, np.zeros((1, 5 - d.shape[1]))])
    k = calib.camera_matrix
    lines = [f"image_width: {calib.image_width}", f"image_height: {calib.image_height}",
             f"camera_name: {camera_name}"]
    lines += _matrix("camera_matrix", k)
    lines.append(f"distortion_model: {model}")
    lines += _matrix("distortion_coefficients", d)
    lines += _matrix("rectification_matrix", np.eye(3))
    lines += _matrix("projection_matrix", np.hstack([k, np.zeros((3, 1))]))
    return "\n".join(lines) + "\n"


# --- import --------------------------------------------------------------------------------------

_MODELS = {"plumb_bob": (5,), "rational_polynomial": (8,)}


def read_camera_info(path: str | Path) -> Calibration:
    """Intrinsics from a ROS ``camera_info`` YAML file (as camera_calibration writes it). The result has
    no belt pose (``tracker calibrate belt`` comes next) and no RMS: it was not calibrated here."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise BadInput(f"{path}: cannot read a ROS camera_info file: {exc}") from None
    doc = _parse(text, path)
    where = f"{path}"

    def integer(name: str) -> int:
        value = doc.get(name)
        if not isinstance(value, str) or not value.strip().lstrip("+").isdigit() or int(value) <= 0:
            raise BadInput(f"{where}: {name}: expected a positive integer, got {value!r}")
        return int(value)

    def matrix(name: str, shapes: tuple[tuple[int, int], ...]) -> np.ndarray:
        node = doc.get(name)
        if not isinstance(node, dict) or "data" not in node:
            raise BadInput(f"{where}: {name}: expected a mapping with rows, cols and data, got {node!r}")
        try:
            rows, cols = int(node.get("rows", "0")), int(node.get("cols", "0"))
            data = [float(v) for v in node["data"]]
        except (TypeError, ValueError):
            raise BadInput(f"{where}: {name}: rows, cols and data must be numbers") from None
        if (rows, cols) not in shapes or len(data) != rows * cols:
            want = " or ".join(f"{r}x{c}" for r, c in shapes)
            raise BadInput(f"{where}: {name}: expected {want} values, got rows {rows}, cols {cols} "
                           f"and {len(data)} values")
        return np.array(data, dtype=np.float64).reshape(rows, cols)

    width, height = integer("image_width"), integer("image_height")
    model = doc.get("distortion_model")
    if model not in _MODELS:
        raise BadInput(f"{where}: distortion_model: expected {' or '.join(_MODELS)}, got {model!r}")
    k = matrix("camera_matrix", ((3, 3),))
    d = matrix("distortion_coefficients", tuple((1, n) for n in _MODELS[model]))
    return Calibration(width, height, k, d, source=where)


def _parse(text: str, path: Path) -> dict:
    """The subset of YAML that camera_info files use: top-level ``key: value`` and one level of nested
    mappings, lists as ``[a, b, ...]`` (possibly over several lines) or as ``- a`` items."""
    doc: dict = {}
    parent: dict | None = None
    pending: tuple[dict, str, str] | None = None  # a flow list still open: (where, key, text so far)
    for number, raw in enumerate(text.splitlines(), 1):
        line = raw.split("#", 1)[0].rstrip()
        if pending is not None:
            target, key, so_far = pending
            so_far += " " + line.strip()
            if "]" in so_far:
                target[key] = _flow_list(so_far, path, number)
                pending = None
            else:
                pending = (target, key, so_far)
            continue
        if not line.strip() or line.strip() in ("---", "..."):
            continue
        indent = len(line) - len(line.lstrip())
        body = line.strip()
        if body.startswith("- "):
            if parent is None or not parent or not isinstance(parent.get(_last(parent)), list):
                raise BadInput(f"{path}:{number}: a list item outside a list")
            parent[_last(parent)].append(body[2:].strip())
            continue
        key, sep, value = body.partition(":")
        if not sep:
            raise BadInput(f"{path}:{number}: expected 'key: value', got {body!r}")
        key, value = key.strip(), value.strip().strip("'\"")
        target = doc if indent == 0 else parent
        if target is None:
            raise BadInput(f"{path}:{number}: indented line outside a mapping")
        if value.startswith("[") and "]" not in value:
            pending = (target, key, value)
        elif value.startswith("["):
            target[key] = _flow_list(value, path, number)
        elif value:
            target[key] = value
        elif indent == 0:
            target[key] = parent = {}
        else:
            target[key] = []  # block list items follow
    if pending is not None:
        raise BadInput(f"{path}: {pending[1]}: a list opened with '[' is never closed")
    return doc


def _flow_list(text: str, path: Path, number: int) -> list[str]:
    inner = text.strip()
    if not (inner.startswith("[") and inner.endswith("]")):
        raise BadInput(f"{path}:{number}: expected a list like [1, 2, 3], got {text!r}")
    return [v.strip() for v in inner[1:-1].split(",") if v.strip()]


def _last(mapping: dict) -> str:
    return next(reversed(mapping))
