"""The compiled heart of the box model (tracker/box.py): where a box's corners and the faces the
camera sees project; how much of each edge window, and of its level pixel, each face covers; and how
far edge points lie from a box's outline.

The box fit evaluates this a few hundred windows x 3 faces x 7 boxes per Jacobian, tens of times
per part and frame; in numpy's whole-array steps that cost 16 ms per part and frame at 560x420,
compiled (numba) a fraction of it. The faces' projection too: in numpy, a few small arrays per
call, it cost 65 us per Jacobian's 7 boxes against 4 compiled; with it and the level pixels that lie
wholly inside or outside a face read without cutting them, a box fit takes 0.55-0.6 of its time
before (2026-12-03: the 65 fits of one 20 mm box's first 30 frames, 525-540 ms -> 296-339 ms).
Plain loops over plain arrays, nothing else.
"""

from __future__ import annotations

import math

import numba
import numpy as np

# Gauss's two points across a pixel (px from its middle): exact for a share linear along its height.
_GAUSS = 0.5 / math.sqrt(3.0)


@numba.njit(cache=True)
def clip(polygons, inner, step, span, level_from, level_to, blur, total, level):  # pragma: no cover (compiled)
    """Fills ``total`` (P, N, F: pixels of each window in each face) and ``level`` (the share of its
    level pixel), for polygons (P, F, 4, 2) and windows from ``inner`` along ``step`` (see box.py)."""
    normal = np.empty((4, 2))
    offset = np.empty(4)
    square = np.empty((12, 2))
    spare = np.empty((12, 2))
    for p in range(polygons.shape[0]):
        for f in range(polygons.shape[1]):
            a = polygons[p, f]
            area2 = 0.0
            for k in range(4):
                j = (k + 1) % 4
                area2 += a[k, 0] * a[j, 1] - a[j, 0] * a[k, 1]
            if area2 == 0.0:
                continue  # a face seen edge-on covers nothing
            sign = 1.0 if area2 > 0 else -1.0
            for k in range(4):
                j = (k + 1) % 4
                # Outward normals whichever way round the projected polygon runs.
                normal[k, 0] = (a[j, 1] - a[k, 1]) * sign
                normal[k, 1] = -(a[j, 0] - a[k, 0]) * sign
                offset[k] = normal[k, 0] * a[k, 0] + normal[k, 1] * a[k, 1]
            for n in range(inner.shape[0]):
                qx, qy, dx, dy = inner[n, 0], inner[n, 1], step[n, 0], step[n, 1]
                lo, hi, stretch_lo, stretch_hi = _interval(normal, offset, qx, qy, dx, dy)
                if blur > 0:
                    # The image's blur, across each edge; along the line it is longer where the edge slants.
                    total[p, n, f] = _blurred(lo, hi, 0.0, span, blur * stretch_lo, blur * stretch_hi)
                    for shift in (-_GAUSS, _GAUSS):
                        lo, hi, stretch_lo, stretch_hi = _interval(normal, offset, qx - shift * dy, qy + shift * dx,
                                                                   dx, dy)
                        share = _blurred(lo, hi, level_from, level_to, blur * stretch_lo, blur * stretch_hi)
                        level[p, n, f] += 0.5 * share / (level_to - level_from)
                    continue
                total[p, n, f] = max(min(hi, span) - max(lo, 0.0), 0.0)
                if _corner_in_strip(a, qx, qy, dx, dy, span):
                    # The window's pixels sum the area of their strip inside the face; its middle line's
                    # length is that area only where the face's edges cross the strip straight.
                    total[p, n, f] = _strip_area(normal, offset, qx, qy, dx, dy, 0.0, span, square, spare)
                # The level pixel: a square along the window, clipped to the face.
                level[p, n, f] = _strip_area(normal, offset, qx, qy, dx, dy, level_from, level_to, square,
                                             spare) / (level_to - level_from)


@numba.njit(cache=True)
def _corner_in_strip(a, qx, qy, dx, dy, span):  # pragma: no cover (compiled)
    """Whether a corner of the face (polygon ``a``) lies in the window's strip of pixels (half a pixel
    either side of its line, and half a pixel beyond its ends): there the pixels' sum and the length of
    the line differ (at a flat part's sharp corner by 0.2-0.3 px, bench/heights_random.py scene 106;
    its fit's RMS 0.027 -> 0.009 px, noiseless). Edges across the strip's ends are left to the line: with
    them summed as areas too, a 60 mm box's views read its height 0.3 mm low on average (the tests' box
    at 10 deg, four noise seeds)."""
    d2 = dx * dx + dy * dy
    if d2 <= 0:
        return False  # a window of no length has no strip (as _strip_area reads it: no area)
    for k in range(4):
        wx, wy = a[k, 0] - qx, a[k, 1] - qy
        along = (wx * dx + wy * dy) / d2
        across = (dx * wy - dy * wx) / d2
        if abs(across) <= 0.5 and -0.5 <= along <= span + 0.5:
            return True
    return False


@numba.njit(cache=True)
def _strip_area(normal, offset, qx, qy, dx, dy, a_from, a_to, square, spare):  # pragma: no cover (compiled)
    """The area (px^2) of the rectangle from ``a_from`` to ``a_to`` px along the window's line and half a
    pixel either side of it (the lens locally conformal) inside the convex polygon (normal . x <= offset)."""
    for c in range(4):
        s_along = a_from if c in (0, 3) else a_to
        s_across = -0.5 if c < 2 else 0.5
        square[c, 0] = qx + s_along * dx - s_across * dy
        square[c, 1] = qy + s_along * dy + s_across * dx
    # Most lie wholly inside a face or wholly outside one of its edges: no cut.
    inside, outside = True, False
    for k in range(4):
        below = above = 0
        for c in range(4):
            d = normal[k, 0] * square[c, 0] + normal[k, 1] * square[c, 1] - offset[k]
            below += d <= 0
            above += d >= 0
        inside = inside and below == 4
        outside = outside or above == 4
    if inside or outside:
        return (a_to - a_from) if inside else 0.0
    count = 4
    for k in range(4):
        count = _cut(square, spare, count, normal[k, 0], normal[k, 1], offset[k])
        square, spare = spare, square
        if count == 0:
            return 0.0
    area = 0.0
    for c in range(count):
        j = (c + 1) % count
        area += square[c, 0] * square[j, 1] - square[j, 0] * square[c, 1]
    d2 = dx * dx + dy * dy
    return min(abs(area) / 2.0 / d2, a_to - a_from) if d2 > 0 else 0.0


@numba.njit(cache=True)
def _interval(normal, offset, qx, qy, dx, dy):  # pragma: no cover (compiled)
    """Where the line q + s d is inside the convex polygon of edges (normal . x <= offset): (lo, hi),
    and for each end how much longer along the line than across its edge a blur is (1 / cos)."""
    lo, hi, stretch_lo, stretch_hi = -np.inf, np.inf, 1.0, 1.0
    length = math.sqrt(dx * dx + dy * dy)
    for k in range(4):
        num = offset[k] - (normal[k, 0] * qx + normal[k, 1] * qy)
        den = normal[k, 0] * dx + normal[k, 1] * dy
        if den == 0:
            if num < 0:
                return 0.0, 0.0, 1.0, 1.0
            continue
        t = num / den
        stretch = math.sqrt(normal[k, 0] ** 2 + normal[k, 1] ** 2) * length / abs(den)
        if den < 0 and t > lo:
            lo, stretch_lo = t, stretch
        elif den > 0 and t < hi:
            hi, stretch_hi = t, stretch
    return lo, hi, stretch_lo, stretch_hi


@numba.njit(cache=True)
def _blurred(lo, hi, a, b, sigma_lo, sigma_hi):  # pragma: no cover (compiled)
    """How much of the pixels [a, b] of a line a face on [lo, hi] covers once blurred: each end a
    Gaussian step (sigma_lo, sigma_hi along the line), Phi((s - lo) / sigma_lo) - Phi((s - hi) / sigma_hi)
    integrated over [a, b] in closed form (the antiderivative of Phi(u) is u Phi(u) + phi(u))."""
    if hi <= lo:
        return 0.0

    def g(u):
        return u * 0.5 * (1.0 + math.erf(u / math.sqrt(2.0))) + math.exp(-0.5 * u * u) / math.sqrt(2.0 * math.pi)

    def rise(edge, sigma):  # the integral over [a, b] of Phi((s - edge) / sigma)
        if edge == -np.inf:
            return b - a
        if edge == np.inf:
            return 0.0
        return sigma * (g((b - edge) / sigma) - g((a - edge) / sigma))

    return rise(lo, sigma_lo) - rise(hi, sigma_hi)


@numba.njit(cache=True)
def _cut(src, dst, count, nx, ny, offset):  # pragma: no cover (compiled)
    """Sutherland-Hodgman: the polygon ``src[:count]`` cut to n . x <= offset, into ``dst``; its count."""
    out = 0
    for c in range(count):
        j = (c + 1) % count
        ax, ay, bx, by = src[c, 0], src[c, 1], src[j, 0], src[j, 1]
        da = nx * ax + ny * ay - offset
        db = nx * bx + ny * by - offset
        if da <= 0:
            dst[out, 0], dst[out, 1] = ax, ay
            out += 1
        if (da < 0 < db) or (db < 0 < da):
            t = da / (da - db)
            dst[out, 0], dst[out, 1] = ax + t * (bx - ax), ay + t * (by - ay)
            out += 1
    return out


@numba.njit(cache=True)
def outline_distances(points, outline, out):  # pragma: no cover (compiled)
    """Fills ``out`` (N,) with each point's signed distance to the nearest edge of the convex polygon
    ``outline`` (K, 2): outside positive."""
    k_count = outline.shape[0]
    area2 = 0.0
    for k in range(k_count):
        j = (k + 1) % k_count
        area2 += outline[k, 0] * outline[j, 1] - outline[j, 0] * outline[k, 1]
    for n in range(points.shape[0]):
        px, py = points[n, 0], points[n, 1]
        best, side = np.inf, 0.0
        for k in range(k_count):
            j = (k + 1) % k_count
            ax, ay = outline[k, 0], outline[k, 1]
            ex, ey = outline[j, 0] - ax, outline[j, 1] - ay
            wx, wy = px - ax, py - ay
            t = min(max((wx * ex + wy * ey) / max(ex * ex + ey * ey, 1e-30), 0.0), 1.0)
            dx, dy = wx - t * ex, wy - t * ey
            dist = math.sqrt(dx * dx + dy * dy)
            if dist < best:
                best, side = dist, ex * wy - ey * wx
        # The polygon's orientation decides which side of an edge is outside.
        out[n] = -best if side * area2 > 0 else best


@numba.njit(cache=True)
def shaded_sums(total, level, kinds, covered, shades, solve, start, prior, low, high, rounds, min_level,
                out_sums, out_shades):  # pragma: no cover (compiled)
    """Fills ``out_sums`` (P, N) with the coverage sum each box predicts for each window: its faces'
    pixels (``total``, P x N x F, and the level pixel's shares ``level``; face f of kind ``kinds[f]``,
    0 the top) each times its kind's shade, over the level pixel's shade (at least ``min_level``).
    The side shades are ``shades`` (2,), or with ``solve`` those that best explain ``covered`` (N,),
    found as boxfit._best_shades describes (from ``start``, held there by ``prior``: each (2,)); they
    go to ``out_shades`` (P, 2)."""
    n_box, n_win, n_face = total.shape
    t = np.empty((n_win, 3))
    lv = np.empty((n_win, 3))
    for p in range(n_box):
        t[:] = 0.0
        lv[:] = 0.0
        for n in range(n_win):
            for f in range(n_face):
                t[n, kinds[f]] += total[p, n, f]
                lv[n, kinds[f]] += level[p, n, f]
        s1, s2 = shades[0], shades[1]
        if solve:
            s1, s2 = start[0], start[1]
            for _ in range(rounds):
                a11 = a12 = a22 = b1 = b2 = 0.0
                for n in range(n_win):
                    w = 1.0 / max(lv[n, 0] + lv[n, 1] * s1 + lv[n, 2] * s2, min_level)
                    x1 = (covered[n] * lv[n, 1] - t[n, 1]) * w
                    x2 = (covered[n] * lv[n, 2] - t[n, 2]) * w
                    y = (t[n, 0] - covered[n] * lv[n, 0]) * w
                    a11 += x1 * x1
                    a12 += x1 * x2
                    a22 += x2 * x2
                    b1 += x1 * y
                    b2 += x2 * y
                a11 += prior[0]
                a22 += prior[1]
                b1 += prior[0] * start[0]
                b2 += prior[1] * start[1]
                det = a11 * a22 - a12 * a12
                s1 = min(max((a22 * b1 - a12 * b2) / det, low), high)
                s2 = min(max((a11 * b2 - a12 * b1) / det, low), high)
        out_shades[p, 0], out_shades[p, 1] = s1, s2
        for n in range(n_win):
            out_sums[p, n] = ((t[n, 0] + t[n, 1] * s1 + t[n, 2] * s2)
                              / max(lv[n, 0] + lv[n, 1] * s1 + lv[n, 2] * s2, min_level))


@numba.njit(cache=True)
def _footprint(params, p, out):  # pragma: no cover (compiled)
    """Fills ``out`` (4, 2) with box ``p``'s footprint corners, counter-clockwise (as
    geometry.rectangle_corners)."""
    x, y, a = params[p, 0], params[p, 1], math.radians(params[p, 2])
    ux, uy = math.cos(a) * params[p, 3] / 2, math.sin(a) * params[p, 3] / 2
    vx, vy = -math.sin(a) * params[p, 4] / 2, math.cos(a) * params[p, 4] / 2
    out[0, 0], out[0, 1] = x - ux - vx, y - uy - vy
    out[1, 0], out[1, 1] = x + ux - vx, y + uy - vy
    out[2, 0], out[2, 1] = x + ux + vx, y + uy + vy
    out[3, 0], out[3, 1] = x - ux + vx, y - uy + vy


@numba.njit(cache=True)
def corner_images(params, rotation, translation, out):  # pragma: no cover (compiled)
    """Fills ``out`` (P, 8, 2) with the normalised images of each box's 8 corners (P rows of x, y,
    angle, length, width, height): its footprint counter-clockwise, then its top (Z = -height)."""
    foot = np.empty((4, 2))
    for p in range(params.shape[0]):
        _footprint(params, p, foot)
        for k in range(8):
            wx, wy = foot[k % 4, 0], foot[k % 4, 1]
            wz = 0.0 if k < 4 else -params[p, 5]
            cx = rotation[0, 0] * wx + rotation[0, 1] * wy + rotation[0, 2] * wz + translation[0]
            cy = rotation[1, 0] * wx + rotation[1, 1] * wy + rotation[1, 2] * wz + translation[1]
            cz = rotation[2, 0] * wx + rotation[2, 1] * wy + rotation[2, 2] * wz + translation[2]
            out[p, k, 0], out[p, k, 1] = cx / cz, cy / cz


@numba.njit(cache=True)
def box_faces(params, rotation, translation, nadir):  # pragma: no cover (compiled)
    """The faces the camera sees of each box (see box.BoxCamera.faces): their polygons (P, F, 4, 2)
    and kinds (F,: 0 the top, 1 a side facing the part's x, 2 one facing its y). The sides seen are
    those of the first box whose outward side the camera's foot ``nadir`` (mm) is on."""
    pts = np.empty((params.shape[0], 8, 2))
    corner_images(params, rotation, translation, pts)
    faces = np.empty((3, 4), dtype=np.int64)
    kinds = np.zeros(3, dtype=np.int64)
    faces[0, 0], faces[0, 1], faces[0, 2], faces[0, 3] = 4, 5, 6, 7
    count = 1
    if params[0, 5] > 0:
        foot = np.empty((4, 2))
        _footprint(params, 0, foot)
        for i in range(4):
            j = (i + 1) % 4
            # The footprint is counter-clockwise: (dy, -dx) points out of it.
            ox, oy = foot[j, 1] - foot[i, 1], foot[i, 0] - foot[j, 0]
            # (A point outside a rectangle is on the outward side of at most two of its edges.)
            if (nadir[0] - foot[i, 0]) * ox + (nadir[1] - foot[i, 1]) * oy > 0 and count < 3:
                faces[count, 0], faces[count, 1], faces[count, 2], faces[count, 3] = i, j, 4 + j, 4 + i
                # Sides 0 and 2 run along the length: they face the part's y.
                kinds[count] = 2 if i % 2 == 0 else 1
                count += 1
    polygons = np.empty((params.shape[0], count, 4, 2))
    for p in range(params.shape[0]):
        for f in range(count):
            for c in range(4):
                polygons[p, f, c, 0] = pts[p, faces[f, c], 0]
                polygons[p, f, c, 1] = pts[p, faces[f, c], 1]
    return polygons, kinds[:count].copy()
