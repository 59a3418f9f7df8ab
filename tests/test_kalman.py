"""The Kalman filter gives filterpy's numbers to the last bit (filterpy itself is not imported at run time)."""

import numpy as np
import pytest

from tracker.config import TrackConfig
from tracker.kalman import make_filter, set_interval, white_noise_block

filterpy = pytest.importorskip("filterpy", reason="filterpy (test dependency) is the reference")


def _reference(z0, cfg):
    from filterpy.kalman import KalmanFilter

    ours = make_filter(z0, cfg)
    ref = KalmanFilter(dim_x=8, dim_z=5)
    ref.x, ref.P, ref.H, ref.R = ours.x.copy(), ours.P.copy(), ours.H.copy(), ours.R.copy()
    return ours, ref


def test_predict_and_update_equal_filterpy_bit_for_bit():
    rng = np.random.default_rng(7)
    cfg = TrackConfig()
    z0 = np.array([100.0, 50.0, 12.0, 80.0, 50.0])
    ours, ref = _reference(z0, cfg)
    for step in range(300):
        dt = float(rng.choice([1 / 60, 1 / 30, 0.05, 0.0171]))
        set_interval(ours, dt, cfg)
        set_interval(ref, dt, cfg)
        ours.predict()
        ref.predict()
        if step % 7 != 3:  # some frames without a measurement
            z = (z0 + rng.normal(0, [2, 2, 3, 1, 1]) + [600 * dt * step, 0, 0, 0, 0]).reshape(5, 1)
            ours.update(z)
            ref.update(z)
        assert np.array_equal(ours.x, ref.x) and np.array_equal(ours.P, ref.P), step


@pytest.mark.parametrize("dt", [1 / 60, 0.1, 2.5])
def test_process_noise_equals_filterpy(dt):
    from filterpy.common import Q_discrete_white_noise

    assert np.array_equal(white_noise_block(dt, 3.7**2), Q_discrete_white_noise(dim=2, dt=dt, var=3.7**2))
