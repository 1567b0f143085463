"""Tare: the one definition of a sensor's resting level, live and offline.

A force-bearing *reference* channel (a BioTac's PDC, a skin cell's force
sensors) says when the sensor rests; every channel tared with it (the
electrodes, the other force sensors) takes its level from the same resting
samples:

* the **resting samples** of a span are those whose reference lies at or
  below the ``rest_percentile`` th percentile of the reference over the span;
* the **resting level** of every channel, the reference included, is its
  median over the resting samples.

``rest_percentile`` says how much of the span is known to be at rest: 100
for a span taken while the sensor does not touch anything (a driver's tare
at start or on ``~/tare``, which refuses while in contact; the pause after a
simulated exploration), :data:`TRIAL_REST_PERCENTILE` for a recorded trial
that touches most of the time (its lowest samples are the rest).  The median
makes the level robust to the odd spike a mean would carry.

The drivers (``streams/``) tare with it on their buffered frames, the lab's
readers on whole trials, the simulated protocols on the pause after a touch:
one function, so a trial replayed through a driver and read offline gets the
same level from the same samples.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import SignalError

__all__ = ["RestingLevel", "resting_level", "TRIAL_REST_PERCENTILE", "MIN_REST_SAMPLES"]

#: Percentile of the reference below which a recorded trial (touching most of the time) rests.
TRIAL_REST_PERCENTILE: float = 5.0
#: Fewest resting samples a level is taken from.
MIN_REST_SAMPLES: int = 3


@dataclass(frozen=True)
class RestingLevel:
    """Resting levels of one sensor.

    Attributes
    ----------
    reference : numpy.ndarray of float64, shape (r,)
        Level of each reference channel (PDC: one; a skin cell's force sensors: three) [counts].
    channels : numpy.ndarray of float64, shape (k,)
        Level of each channel tared with it (electrodes) [counts]; empty when none.
    samples : int
        Resting samples the levels were taken from.
    """

    reference: np.ndarray
    channels: np.ndarray
    samples: int


def resting_level(reference: np.ndarray, channels: np.ndarray | None = None, *,
                  rest_percentile: float = 100.0) -> RestingLevel:
    """The resting level of a sensor over a span of samples (module docstring).

    Parameters
    ----------
    reference : array_like, shape (n,) or (r, n)
        The force-bearing channel(s) over the span, in counts; NaN marks an
        unreadable sample (never a resting one). With several rows (a skin
        cell's three force sensors) a sample rests when the mean of the rows does.
    channels : array_like, shape (k, n), optional
        Channels tared with the reference, sampled with it (NaN: unreadable).
    rest_percentile : float
        ``(0, 100]``: the share of the span known to rest (100: all of it).

    Returns
    -------
    RestingLevel

    Raises
    ------
    SignalError
        For shapes that do not match, a percentile outside ``(0, 100]``, or
        fewer than :data:`MIN_REST_SAMPLES` readable resting samples.
    """
    ref = np.asarray(reference, dtype=np.float64)
    one_row = ref.ndim == 1
    ref = ref[None, :] if one_row else ref
    if ref.ndim != 2 or ref.shape[0] < 1:
        raise SignalError(f"reference must be (n,) or (r, n), got shape {np.shape(reference)}")
    n = ref.shape[1]
    other = np.zeros((0, n)) if channels is None else np.asarray(channels, dtype=np.float64)
    if other.ndim != 2 or other.shape[1] != n:
        raise SignalError(f"channels must be (k, {n}) like the reference's {n} samples, got {np.shape(channels)}")
    if not (0.0 < float(rest_percentile) <= 100.0):
        raise SignalError(f"rest_percentile must be in (0, 100], got {rest_percentile}")
    combined = ref.mean(axis=0)
    readable = np.isfinite(combined) & np.isfinite(other).all(axis=0)
    if np.count_nonzero(readable) < MIN_REST_SAMPLES:
        raise SignalError(f"only {int(np.count_nonzero(readable))} readable samples to tare on "
                          f"(at least {MIN_REST_SAMPLES})")
    cut = np.percentile(combined[readable], float(rest_percentile))
    rest = readable & (combined <= cut)
    count = int(np.count_nonzero(rest))
    if count < MIN_REST_SAMPLES:
        raise SignalError(f"only {count} resting samples at or below the {rest_percentile}th percentile "
                          f"(at least {MIN_REST_SAMPLES})")
    return RestingLevel(reference=np.median(ref[:, rest], axis=1), channels=np.median(other[:, rest], axis=1),
                        samples=count)
