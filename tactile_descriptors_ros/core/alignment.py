"""Zero-order hold: put a slow signal on a fast signal's time base.

The vibration signal S and the deformation signal V of one cell are sampled
at different rates (BioTac PAC 2.2 kHz vs electrodes 50-100 Hz; skin
accelerometer 1 kHz vs force 250 Hz).  The correlations of paper eq. 4-5 and
9-10 need pairs of samples, so we correlate on the faster signal's time base
with the slower one *held*: each slow sample keeps its value until the next
one arrives, by the message time stamps.  Hold invents no
values between samples and keeps integer data integer.
"""

from __future__ import annotations

import numpy as np

from ..errors import SignalError

__all__ = ["hold_indices", "zero_order_hold"]


def _as_stamps(t: np.ndarray, name: str) -> np.ndarray:
    arr = np.asarray(t)
    if arr.ndim != 1:
        raise SignalError(f"{name} must be one-dimensional, got shape {arr.shape}")
    if arr.size and not np.issubdtype(arr.dtype, np.integer):
        if not np.all(np.isfinite(arr)):
            raise SignalError(f"{name} has non-finite time stamps")
    if arr.size > 1 and np.any(np.diff(arr) < 0):
        raise SignalError(f"{name} must be sorted in time (non-decreasing)")
    return arr


def hold_indices(t_slow_ns: np.ndarray, t_fast_ns: np.ndarray) -> np.ndarray:
    """Index of the slow sample held at each fast sample time.

    Parameters
    ----------
    t_slow_ns : array_like of int64, shape (n_slow,)
        Slow sample times (non-decreasing).
    t_fast_ns : array_like of int64, shape (n_fast,)
        Fast sample times (non-decreasing).

    Returns
    -------
    numpy.ndarray of intp, shape (n_fast,)
        ``i`` such that ``t_slow[i] <= t_fast < t_slow[i+1]``; -1 where no slow
        sample has arrived yet (those fast samples have nothing to pair with).
    """
    ts = _as_stamps(t_slow_ns, "t_slow_ns")
    tf = _as_stamps(t_fast_ns, "t_fast_ns")
    return np.searchsorted(ts, tf, side="right").astype(np.intp) - 1


def zero_order_hold(
    t_slow_ns: np.ndarray, v_slow: np.ndarray, t_fast_ns: np.ndarray, axis: int = -1
) -> tuple[np.ndarray, np.ndarray]:
    """Hold ``v_slow`` onto the fast time base.

    Parameters
    ----------
    t_slow_ns : array_like, shape (n_slow,)
        Slow sample times in ns.
    v_slow : array_like, shape (..., n_slow, ...)
        Slow samples, the time axis being ``axis``.
    t_fast_ns : array_like, shape (n_fast,)
        Fast sample times in ns.
    axis : int, default -1
        Time axis of ``v_slow``.

    Returns
    -------
    held : numpy.ndarray
        ``v_slow`` at the fast times, same dtype, time axis of length n_fast
        (entries where ``valid`` is False hold the first slow sample and must
        not be used).
    valid : numpy.ndarray of bool, shape (n_fast,)
        False for fast samples taken before the first slow sample.
    """
    v = np.asarray(v_slow)
    if v.shape[axis] != np.asarray(t_slow_ns).shape[0]:
        raise SignalError(
            f"v_slow has {v.shape[axis]} samples along axis {axis} but t_slow_ns has "
            f"{np.asarray(t_slow_ns).shape[0]} stamps"
        )
    idx = hold_indices(t_slow_ns, t_fast_ns)
    valid = idx >= 0
    if v.shape[axis] == 0:
        shape = list(v.shape)
        shape[axis] = idx.shape[0]
        return np.zeros(shape, dtype=v.dtype), np.zeros(idx.shape[0], dtype=bool)
    return np.take(v, np.maximum(idx, 0), axis=axis), valid
