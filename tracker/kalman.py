"""Kalman filter: a part's pose, velocity, angle and size.

State  x = [x_mm, y_mm, vx_mm_s, vy_mm_s, angle_deg, omega_deg_s, length_mm, width_mm]
Measured z = [x_mm, y_mm, angle_deg, length_mm, width_mm]
Position and angle move at constant (noisy) rates; the sizes are constant up to a
slow random walk (a part's apparent size changes only through noise).

The filter is filterpy's ``KalmanFilter`` predict and update, the same equations in the
same order, so the numbers are identical to the last bit (``tests/test_kalman.py`` checks
it against filterpy). Importing filterpy imports scipy and every filter it has: 0.6 s
of a process's start, more than the vision core spends on 300 frames.
"""

from __future__ import annotations

import functools

import numpy as np

from tracker.config import TrackConfig

X, Y, VX, VY, ANGLE, OMEGA, LENGTH, WIDTH = range(8)


class KalmanFilter:
    """Linear Kalman filter with filterpy's attribute names (x, P, F, Q, H, R) and equations."""

    def __init__(self, dim_x: int, dim_z: int) -> None:
        self.x = np.zeros((dim_x, 1))
        self.P = np.eye(dim_x)
        self.F = np.eye(dim_x)
        self.Q = np.eye(dim_x)
        self.H = np.zeros((dim_z, dim_x))
        self.R = np.eye(dim_z)
        self._I = np.eye(dim_x)

    def predict(self) -> None:
        """x = Fx, P = FPF' + Q."""
        self.x = np.dot(self.F, self.x)
        self.P = np.dot(np.dot(self.F, self.P), self.F.T) + self.Q

    def update(self, z: np.ndarray) -> None:
        """Measurement ``z`` (dim_z x 1); the covariance in Joseph form, as filterpy does."""
        H, R = self.H, self.R
        y = z - np.dot(H, self.x)
        PHT = np.dot(self.P, H.T)  # noqa: N806 - the textbook's names
        S = np.dot(H, PHT) + R  # noqa: N806
        K = np.dot(PHT, np.linalg.inv(S))  # noqa: N806
        self.x = self.x + np.dot(K, y)
        I_KH = self._I - np.dot(K, H)  # noqa: N806
        self.P = np.dot(np.dot(I_KH, self.P), I_KH.T) + np.dot(np.dot(K, R), K.T)


def white_noise_block(dt_s: float, var: float) -> np.ndarray:
    """Process noise of a (position, rate) pair under piecewise-constant white acceleration
    (filterpy's ``Q_discrete_white_noise(dim=2)``, same arithmetic)."""
    return np.array([[.25 * dt_s**4, .5 * dt_s**3], [.5 * dt_s**3, dt_s**2]]) * var


def make_filter(z: np.ndarray, cfg: TrackConfig) -> KalmanFilter:
    """A filter initialised at measurement ``z``, velocity unknown."""
    kf = KalmanFilter(dim_x=8, dim_z=5)
    kf.H = np.zeros((5, 8))
    for row, col in enumerate((X, Y, ANGLE, LENGTH, WIDTH)):
        kf.H[row, col] = 1.0
    p, a, s = cfg.position_sigma_mm**2, cfg.angle_sigma_deg**2, cfg.size_sigma_mm**2
    kf.R = np.diag([p, p, a, s, s])
    kf.x = np.array([[z[0]], [z[1]], [0.0], [0.0], [z[2]], [0.0], [z[3]], [z[4]]])
    v0, w0 = cfg.initial_velocity_sigma_mm_s**2, cfg.initial_angular_rate_sigma_deg_s**2
    # A new part's velocity is unknown: a wide prior lets the second measurement set it.
    kf.P = np.diag([p, p, v0, v0, a, w0, s, s])
    return kf


def set_interval(kf: KalmanFilter, dt_s: float, cfg: TrackConfig) -> None:
    """Transition and process noise for a step of ``dt_s`` seconds (frames need not be evenly spaced)."""
    kf.F, kf.Q = _transition(dt_s, cfg)


@functools.lru_cache(maxsize=256)
def _transition(dt_s: float, cfg: TrackConfig) -> tuple[np.ndarray, np.ndarray]:
    # Cached: a camera's frame interval takes few distinct values. The filter does not modify F or Q.
    f = np.eye(8)
    f[X, VX] = f[Y, VY] = f[ANGLE, OMEGA] = dt_s
    q = np.zeros((8, 8))
    # Piecewise-constant white acceleration for each (position, rate) pair.
    for pos, rate, sigma in ((X, VX, cfg.accel_sigma_mm_s2), (Y, VY, cfg.accel_sigma_mm_s2),
                             (ANGLE, OMEGA, cfg.angular_accel_sigma_deg_s2)):
        block = white_noise_block(dt_s, sigma**2)
        q[np.ix_((pos, rate), (pos, rate))] = block
    q[LENGTH, LENGTH] = q[WIDTH, WIDTH] = (cfg.size_rate_sigma_mm_s * dt_s) ** 2
    f.flags.writeable = q.flags.writeable = False
    return f, q
