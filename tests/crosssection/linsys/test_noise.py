"""Width error model and its scale measured on the data."""
from __future__ import annotations

import numpy as np
import pytest

from crosssection.linsys import estimate_noise_scale
from crosssection.linsys.noise import width_weights


@pytest.mark.parametrize("sigma", [0.03, 0.1, 0.6])
def test_noise_scale_follows_the_data(sigma):
    rng = np.random.default_rng(int(sigma * 100))
    n = rng.integers(1, 5, 400)
    e = n + rng.normal(0, sigma, 400)
    s_model = np.full(400, 0.3)
    k = estimate_noise_scale(e, s_model)
    if sigma < 0.2:
        assert k == pytest.approx(max(sigma / 0.3, 0.25), rel=0.25)
    else:
        assert k > 0.8  # half-layer errors never make the model more confident
    assert estimate_noise_scale(e[:3], s_model[:3]) == 1.0


def test_width_weights_model():
    e = np.array([1.0, 3.0, np.nan, 5.0])
    wts = width_weights(e, reliability=np.array([1.0, 2.0, 1.0, np.nan]), noise_scale=0.5,
                        noise_growth=0.05)
    np.testing.assert_allclose(wts.sigma, 0.5 * np.array([0.3, 0.4, 0.3, 0.5]))
    # the default model is this one
    np.testing.assert_allclose(width_weights(e, noise_scale=0.5).sigma, wts.sigma)
    np.testing.assert_allclose(wts.weights, [1 / 0.15 ** 2, 2 / 0.2 ** 2, 0, 0])
    np.testing.assert_array_equal(wts.layers, [1, 3, 1, 5])
    assert np.all(wts.weights_eff > 0)
    assert wts.weights_eff[2] == pytest.approx(1e-6 * wts.weights.max())
    assert wts.noise_scale == 0.5


def test_width_weights_rejects_bad_arguments():
    with pytest.raises(ValueError, match="noise_scale"):
        width_weights(np.ones(3), noise_scale="fast")
    with pytest.raises(ValueError, match="reliability"):
        width_weights(np.ones(3), reliability=np.ones(2))


def test_width_error_grows_only_where_thick_widths_do_not_resolve_layers():
    """Thick stacks whose estimates sit on integers (a calibrated, sharp scan) get the thin
    stacks' error; estimates spread between integers (no calibration: w = n h read for
    h (n + 0.4 sqrt n)) keep the growing error, and so do scans with few thick stacks."""
    from crosssection.linsys.noise import NOISE_GROWTH, estimate_growth

    rng = np.random.default_rng(3)
    n = rng.integers(5, 16, 40)
    assert estimate_growth(n + rng.normal(0, 0.08, 40)) == 0.0
    assert estimate_growth(n + 0.4 * np.sqrt(n)) == NOISE_GROWTH
    assert estimate_growth(n + rng.uniform(-0.5, 0.5, 40)) == NOISE_GROWTH
    assert estimate_growth(np.r_[np.ones(30), 7.0, 9.0, np.nan]) == NOISE_GROWTH
    wts = width_weights(np.r_[np.ones(10), n + 0.01], noise_scale=1.0)
    np.testing.assert_allclose(wts.sigma, 0.3)
    with pytest.raises(ValueError, match="noise_growth"):
        width_weights(np.ones(3), noise_growth="fast")
