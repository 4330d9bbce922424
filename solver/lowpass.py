"""A 2nd-order Butterworth low-pass run forward and backward (zero phase lag), as biomechanics filters kinematics.

The same filter as scipy.signal's `butter(2, wn)` with `filtfilt(b, a, x, axis=0)` and its defaults (odd
extension of padlen = 3 max(len(a), len(b)) = 9 samples at each end, each pass started in the steady state
of its first sample, `lfilter_zi`), written on scipy.linalg: importing scipy.signal loads scipy.stats, 0.5 s of
a command's 4-7 s, for these 20 lines. tests/solver/test_lowpass.py checks it against scipy.signal.

    coefficients   bilinear transform of the analogue Butterworth s^2 + sqrt(2) s + 1 with its cutoff prewarped,
                   K = tan(pi wn / 2) (Oppenheim & Schafer, Discrete-Time Signal Processing, 3rd ed., sec. 7.2)
    one pass       y[n] + a1 y[n-1] + a2 y[n-2] = b0 x[n] + b1 x[n-1] + b2 x[n-2], the recursion as the
                   forward substitution of a lower triangular banded system (LAPACK's dtbtrs, no pivoting)
"""
from __future__ import annotations

import numpy as np
from scipy.linalg.lapack import dtbtrs

__all__ = ["PADLEN", "butter2", "filtfilt2"]

#: [samples] the odd extension at each end: scipy's filtfilt default, 3 max(len(a), len(b)) for 3 coefficients
PADLEN = 9


def butter2(wn: float) -> tuple[np.ndarray, np.ndarray]:
    """(b, a), each (3,): the 2nd-order digital Butterworth low-pass with cutoff wn (0 < wn < 1, 1 the Nyquist
    frequency), a[0] = 1 (Oppenheim & Schafer, sec. 7.2; scipy.signal.butter(2, wn)).

    Raises:
        ValueError: wn not in (0, 1).
    """
    if not 0.0 < wn < 1.0:
        raise ValueError(f"the cutoff must be between 0 and the Nyquist frequency (0 < wn < 1), got {wn}")
    k = np.tan(0.5 * np.pi * wn)
    norm = 1.0 / (1.0 + np.sqrt(2.0) * k + k * k)
    b = k * k * norm * np.array([1.0, 2.0, 1.0])
    a = np.array([1.0, 2.0 * (k * k - 1.0) * norm, (1.0 - np.sqrt(2.0) * k + k * k) * norm])
    return b, a


def _one_pass(b: np.ndarray, a: np.ndarray, x: np.ndarray) -> np.ndarray:
    """(n, c) the recursion over the columns of x (n, c), started in the steady state of x[0] (scipy's
    `lfilter(b, a, x, axis=0, zi=lfilter_zi(b, a) * x[0])`): the state after a constant input g x[0], g = sum b /
    sum a, enters the first two equations as z0 = (g - b0) x[0], z1 = (b2 - a2 g) x[0] (transposed direct form II)."""
    gain = b.sum() / a.sum()
    rhs = b[0] * x
    rhs[1:] += b[1] * x[:-1]
    rhs[2:] += b[2] * x[:-2]
    rhs[0] += (gain - b[0]) * x[0]
    rhs[1] += (b[2] - a[2] * gain) * x[0]
    band = np.zeros((3, len(x)))
    band[0], band[1, :-1], band[2, :-2] = 1.0, a[1], a[2]
    y, info = dtbtrs(band, rhs, uplo="L")
    if info != 0:
        raise np.linalg.LinAlgError(f"dtbtrs returned {info}")
    return y


def filtfilt2(b: np.ndarray, a: np.ndarray, x: np.ndarray) -> np.ndarray:
    """(n, c) x (n, c) filtered forward and backward along axis 0 (scipy.signal.filtfilt(b, a, x, axis=0) with its
    default odd extension of `PADLEN` samples): zero phase lag, the magnitude response squared.

    Raises:
        ValueError: n <= PADLEN (too few samples to extend).
    """
    x = np.asarray(x, float)
    n = len(x)
    if n <= PADLEN:
        raise ValueError(f"the signal has {n} samples; the zero-lag filter needs more than {PADLEN}")
    ext = np.concatenate([2 * x[0] - x[PADLEN:0:-1], x, 2 * x[-1] - x[-2:-PADLEN - 2:-1]])
    y = _one_pass(b, a, ext)
    y = _one_pass(b, a, y[::-1].copy())[::-1]
    return y[PADLEN:-PADLEN].copy()
