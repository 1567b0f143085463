"""The resting level (core.tare): known answers, the trial and at-rest readings, bad input."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tactile_descriptors_ros.core.tare import MIN_REST_SAMPLES, TRIAL_REST_PERCENTILE, resting_level
from tactile_descriptors_ros.errors import SignalError


def test_a_span_at_rest_gives_each_channels_median():
    pdc = np.array([10.0, 12.0, 11.0, 50.0, 9.0])
    el = np.array([[100.0, 101.0, 99.0, 140.0, 98.0], [7.0, 7.0, 8.0, 9.0, 6.0]])
    lvl = resting_level(pdc, el)
    assert lvl.reference.tolist() == [11.0] and lvl.channels.tolist() == [100.0, 7.0] and lvl.samples == 5


def test_a_touching_trial_rests_on_its_lowest_samples():
    # 95 touching samples at 400 counts, 5 resting ones around 20: the level is theirs, the
    # electrodes' level is theirs over the same samples
    rng = np.random.default_rng(3)
    pdc = np.r_[np.full(95, 400.0) + rng.normal(0, 5, 95), [19.0, 20.0, 21.0, 20.0, 22.0]]
    el = np.vstack([np.r_[np.full(95, 900.0), [500.0, 501.0, 502.0, 503.0, 504.0]]])
    lvl = resting_level(pdc, el, rest_percentile=TRIAL_REST_PERCENTILE)
    assert lvl.reference[0] == 20.0 and lvl.channels[0] == 502.0 and lvl.samples == 5


def test_three_force_sensors_rest_together():
    f = np.array([[10.0, 11.0, 30.0, 12.0], [20.0, 21.0, 40.0, 22.0], [5.0, 6.0, 25.0, 7.0]])
    lvl = resting_level(f, rest_percentile=75.0)  # the mean force's 75th percentile leaves out the press
    assert lvl.reference.tolist() == [11.0, 21.0, 6.0] and lvl.samples == 3


def test_unreadable_samples_are_never_resting_ones():
    pdc = np.array([np.nan, 5.0, 6.0, 7.0, np.nan])
    el = np.array([[1e9, 1.0, 2.0, 3.0, 1e9]])
    lvl = resting_level(pdc, el)
    assert lvl.reference[0] == 6.0 and lvl.channels[0] == 2.0 and lvl.samples == 3


@settings(max_examples=100, deadline=None)
@given(st.lists(st.integers(0, 4095), min_size=MIN_REST_SAMPLES, max_size=200), st.integers(0, 2**32 - 1))
def test_the_level_depends_on_the_samples_not_their_order(values, seed):
    pdc = np.asarray(values, dtype=np.float64)
    el = np.vstack([pdc * 2 + 1, -pdc])
    order = np.random.default_rng(seed).permutation(pdc.size)
    a, b = resting_level(pdc, el), resting_level(pdc[order], el[:, order])
    assert np.array_equal(a.reference, b.reference) and np.array_equal(a.channels, b.channels)
    assert a.reference[0] == np.median(pdc) and a.channels[0] == np.median(pdc * 2 + 1)


@pytest.mark.parametrize("kwargs, match", [
    ({"reference": [1.0, 2.0]}, "readable samples"),
    ({"reference": [1.0, 2.0, 3.0], "channels": [[1.0, 2.0]]}, r"channels must be \(k, 3\)"),
    ({"reference": [1.0, 2.0, 3.0], "rest_percentile": 0.0}, "rest_percentile"),
    ({"reference": [1.0, 2.0, 3.0], "rest_percentile": 150.0}, "rest_percentile"),
    ({"reference": [1.0, 2.0, 3.0, 4.0, 5.0, 6.0], "rest_percentile": 10.0}, "resting samples"),
    ({"reference": [[[1.0]]]}, "reference must be"),
])
def test_bad_spans_are_signal_errors(kwargs, match):
    with pytest.raises(SignalError, match=match):
        resting_level(**kwargs)
