"""The zero-lag Butterworth (`solver.lowpass`) against scipy.signal's butter and filtfilt, an independent
implementation (its lfilter is a direct-form recursion in C; ours a banded triangular solve)."""
import numpy as np
import pytest
import scipy.signal

from solver.lowpass import PADLEN, butter2, filtfilt2


@pytest.mark.parametrize("wn", [0.005, 0.05, 0.3, 0.95])
def test_coefficients_are_scipys(wn):
    b, a = butter2(wn)
    B, A = scipy.signal.butter(2, wn)
    np.testing.assert_allclose(b, B, rtol=1e-12, atol=1e-18)
    np.testing.assert_allclose(a, A, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize(("wn", "n"), [(0.02, 2000), (0.1, 300), (0.5, PADLEN + 1), (0.9, 57)])
def test_filtfilt_is_scipys(wn, n):
    """A random walk in 4 channels (drift, so the ends' odd extension and steady start matter), to 1e-10 of its
    range: the two recursions round differently, by ~1e-13 at the lowest cutoff."""
    x = np.cumsum(np.random.default_rng(7).normal(size=(n, 4)), axis=0) + [0.0, 100.0, -5.0, 1e3]
    b, a = butter2(wn)
    ours = filtfilt2(b, a, x)
    ref = scipy.signal.filtfilt(*scipy.signal.butter(2, wn), x, axis=0)
    np.testing.assert_allclose(ours, ref, rtol=0, atol=1e-10 * np.ptp(x))


def test_constant_passes_unchanged():
    """A constant: the filter's DC gain is 1 and each pass starts in its steady state, so it comes back exactly."""
    x = np.full((40, 2), [3.5, -2.0])
    np.testing.assert_allclose(filtfilt2(*butter2(0.2), x), x, rtol=1e-13)


def test_bad_input():
    with pytest.raises(ValueError, match="Nyquist"):
        butter2(1.0)
    with pytest.raises(ValueError, match="more than 9"):
        filtfilt2(*butter2(0.2), np.zeros((PADLEN, 2)))
