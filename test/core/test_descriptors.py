"""Hjorth parameters and correlations: known answers, independent implementations, properties."""

from __future__ import annotations

import warnings

import antropy
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from scipy import stats

from tactile_descriptors_ros.core.descriptors import (
    Quality,
    average_ranks,
    hjorth,
    pearson,
    spearman,
)
from tactile_descriptors_ros.errors import SignalError


# ----------------------------------------------------------------- known answers
@pytest.mark.parametrize("f_hz,fs_hz", [(5.0, 100.0), (10.0, 1000.0), (200.0, 2200.0), (37.0, 250.0)])
def test_sine_mobility_is_2_sin_pi_f_over_fs_times_fs(f_hz, fs_hz):
    n = int(fs_hz * 20)  # 20 s: edge effects of the finite window below 1e-3
    t = np.arange(n) / fs_hz
    h = hjorth(3.0 * np.sin(2 * np.pi * f_hz * t + 0.3), fs_hz)
    expected = 2 * np.sin(np.pi * f_hz / fs_hz) * fs_hz
    assert float(h.mobility) == pytest.approx(expected, rel=1e-3)
    assert float(h.complexity) == pytest.approx(1.0, abs=2e-3)
    assert float(h.activity) == pytest.approx(4.5, rel=1e-3)  # A^2 / 2
    assert int(h.quality) == 0


def test_mobility_is_a_frequency_independent_of_sampling_rate():
    # The same physical 8 Hz sine sampled at 500 Hz and 2 kHz: Mobility ~ 2 pi 8 rad/s.
    values = []
    for fs in (500.0, 2000.0):
        t = np.arange(int(fs * 10)) / fs
        values.append(float(hjorth(np.sin(2 * np.pi * 8 * t), fs).mobility))
    assert values[0] == pytest.approx(2 * np.pi * 8, rel=2e-3)
    assert values[1] == pytest.approx(values[0], rel=2e-3)


def test_white_noise_mobility_and_complexity():
    # For white noise var(diff) = 2 var, so Mobility = sqrt(2) fs; diff of diff
    # has variance 6 var, so Mobility(S') = sqrt(3) fs and Complexity = sqrt(3/2).
    rng = np.random.default_rng(1)
    x = rng.normal(size=200_000)
    h = hjorth(x, 1.0)
    assert float(h.mobility) == pytest.approx(np.sqrt(2), rel=1e-2)
    assert float(h.complexity) == pytest.approx(np.sqrt(1.5), rel=1e-2)


def test_dc_offset_of_1e6_does_not_change_anything():
    rng = np.random.default_rng(2)
    x = rng.normal(size=(4, 3000))
    a = hjorth(x, 100.0)
    b = hjorth(x + 1e6, 100.0)
    np.testing.assert_allclose(b.activity, a.activity, rtol=1e-8)
    np.testing.assert_allclose(b.mobility, a.mobility, rtol=1e-8)
    np.testing.assert_allclose(b.complexity, a.complexity, rtol=1e-7)
    y = rng.normal(size=(4, 3000))
    np.testing.assert_allclose(pearson(x + 1e6, y - 1e6), pearson(x, y), atol=1e-9)
    np.testing.assert_allclose(spearman(x + 1e6, y), spearman(x, y), atol=1e-12)


# ------------------------------------------------------ independent implementations
def test_hjorth_agrees_with_antropy():
    rng = np.random.default_rng(3)
    x = np.cumsum(rng.normal(size=(6, 1000)), axis=1)
    mob, com = antropy.hjorth_params(x, axis=-1)
    h = hjorth(x, 1.0)
    np.testing.assert_allclose(h.mobility, mob, rtol=1e-10)
    np.testing.assert_allclose(h.complexity, com, rtol=1e-10)
    np.testing.assert_allclose(h.activity, np.var(x, axis=1), rtol=1e-12)


def test_hjorth_mobility_scales_with_fs_against_antropy():
    rng = np.random.default_rng(4)
    x = rng.normal(size=500)
    mob, _ = antropy.hjorth_params(x)
    assert float(hjorth(x, 2200.0).mobility) == pytest.approx(mob * 2200.0, rel=1e-12)


def test_correlations_agree_with_scipy_on_random_and_tied_data():
    rng = np.random.default_rng(5)
    for a, b in [
        (rng.normal(size=(5, 400)), rng.normal(size=(5, 400))),
        (rng.integers(0, 8, size=(5, 400)), rng.integers(0, 8, size=(5, 400))),  # heavy ties
        (rng.integers(0, 4096, size=(5, 400)), rng.normal(size=(5, 400))),
    ]:
        r = pearson(a, b)
        rho = spearman(a, b)
        for i in range(5):
            assert r[i] == pytest.approx(stats.pearsonr(a[i], b[i]).statistic, abs=1e-12)
            assert rho[i] == pytest.approx(stats.spearmanr(a[i], b[i]).statistic, abs=1e-12)


def test_correlation_broadcasts_over_leading_axes():
    rng = np.random.default_rng(6)
    s = rng.normal(size=(3, 1, 200))
    v = rng.normal(size=(1, 4, 200))
    r = pearson(s, v)
    assert r.shape == (3, 4)
    assert r[2, 3] == pytest.approx(stats.pearsonr(s[2, 0], v[0, 3]).statistic, abs=1e-12)


def test_axis_argument():
    rng = np.random.default_rng(7)
    x = rng.normal(size=(300, 3))
    h0 = hjorth(x, 10.0, axis=0)
    h1 = hjorth(x.T, 10.0)
    np.testing.assert_allclose(h0.mobility, h1.mobility)
    y = rng.normal(size=(300, 3))
    np.testing.assert_allclose(spearman(x, y, axis=0), spearman(x.T, y.T))


def test_counting_ranks_equal_scipy_rankdata():
    rng = np.random.default_rng(8)
    x = rng.integers(-512, 512, size=(7, 1000))
    np.testing.assert_array_equal(average_ranks(x), stats.rankdata(x, axis=1))
    x16 = rng.integers(0, 4096, size=(3, 50)).astype(np.uint16)
    np.testing.assert_array_equal(average_ranks(x16, axis=1), stats.rankdata(x16, axis=1))


# ------------------------------------------------------------ degenerate inputs
def test_degenerate_inputs_have_documented_values_and_flags():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        flat = hjorth(np.full(100, 7.0), 100.0)
        assert (float(flat.mobility), float(flat.complexity), int(flat.quality)) == (0.0, 0.0, Quality.FLAT)
        short = hjorth([1.0, 2.0], 100.0)
        assert int(short.quality) & Quality.SHORT and float(short.mobility) == 0.0
        assert float(short.activity) == 0.25
        empty = hjorth(np.zeros(0), 100.0)
        assert int(empty.quality) == Quality.SHORT and float(empty.activity) == 0.0
        nan = hjorth([1.0, np.nan, 3.0, 2.0], 100.0)
        assert int(nan.quality) == Quality.NONFINITE
        assert (float(nan.activity), float(nan.mobility), float(nan.complexity)) == (0.0, 0.0, 0.0)
        ramp = hjorth(np.arange(50.0), 1.0)
        assert int(ramp.quality) == Quality.FLAT and float(ramp.complexity) == 0.0
        huge = hjorth(np.array([1e300, -1e300, 1e300, -1e300, 5.0]), 1.0)
        assert int(huge.quality) & Quality.OVERFLOW
        assert np.isfinite(huge.activity) and np.isfinite(huge.mobility)
        r, q = pearson(np.ones(10), np.arange(10.0), return_quality=True)
        assert float(r) == 0.0 and int(q) == Quality.FLAT
        r, q = spearman([1.0, np.inf, 2.0, 3.0], [1.0, 2.0, 3.0, 4.0], return_quality=True)
        assert float(r) == 0.0 and int(q) == Quality.NONFINITE


def test_tiny_amplitudes_are_not_flat():
    rng = np.random.default_rng(9)
    x = rng.normal(size=1000)
    a, b = hjorth(x, 1.0), hjorth(x * 1e-30, 1.0)
    assert int(b.quality) == 0
    assert float(b.mobility) == pytest.approx(float(a.mobility), rel=1e-12)
    assert float(b.activity) == pytest.approx(float(a.activity) * 1e-60, rel=1e-12)


def test_bad_arguments_raise_signal_error():
    with pytest.raises(SignalError):
        hjorth(np.ones(10), 0.0)
    with pytest.raises(SignalError):
        hjorth(np.array(["a", "b"]), 1.0)
    with pytest.raises(SignalError, match="same number of samples"):
        pearson(np.ones(10), np.ones(11))
    with pytest.raises(SignalError):
        spearman(np.ones((2, 10)), np.ones((3, 10)))


# -------------------------------------------------------------------- properties
finite = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False, allow_infinity=False)


@settings(max_examples=150, deadline=None)
@given(hnp.arrays(np.float64, st.integers(0, 60), elements=finite), st.floats(1.0, 1e4))
def test_hjorth_never_returns_nan_or_warns(x, fs):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        h = hjorth(x, fs)
    for v in (h.activity, h.mobility, h.complexity):
        assert np.isfinite(v)
        assert v >= 0


@settings(max_examples=150, deadline=None)
@given(hnp.arrays(np.float64, st.integers(3, 80), elements=finite),
       st.floats(-1e5, 1e5), st.floats(0.01, 100.0))
def test_mobility_and_complexity_invariant_to_offset_and_scale(x, offset, gain):
    h0 = hjorth(x, 10.0)
    h1 = hjorth(x * gain + offset, 10.0)
    if int(h0.quality) or int(h1.quality):
        return  # flat at float rounding: documented zeros, covered above
    np.testing.assert_allclose(h1.mobility, h0.mobility, rtol=1e-5)


@settings(max_examples=150, deadline=None)
@given(st.integers(3, 60).flatmap(lambda n: st.tuples(
    hnp.arrays(np.int64, n, elements=st.integers(0, 15)),
    hnp.arrays(np.int64, n, elements=st.integers(0, 4095)))))
def test_spearman_matches_scipy_with_ties(pair):
    a, b = pair
    rho, q = spearman(a, b, return_quality=True)
    if int(q) & Quality.FLAT:
        assert float(rho) == 0.0
        return
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        expected = stats.spearmanr(a, b).statistic
    assert float(rho) == pytest.approx(expected, abs=1e-9)
    assert -1.0 <= float(rho) <= 1.0


@settings(max_examples=100, deadline=None)
@given(hnp.arrays(np.float64, st.tuples(st.integers(1, 3), st.integers(3, 50)), elements=finite))
def test_pearson_of_a_signal_with_itself_is_one_unless_flat(x):
    r, q = pearson(x, x, return_quality=True)
    for ri, qi in zip(np.ravel(r), np.ravel(q)):
        assert (qi & Quality.FLAT and ri == 0.0) or ri == pytest.approx(1.0, abs=1e-9)


@settings(max_examples=60, deadline=None)
@given(hnp.arrays(np.float32, st.integers(10, 200),
                  elements=st.floats(-1000, 1000, width=32, allow_nan=False, allow_infinity=False)))
def test_float32_input_equals_float64_of_the_same_values(x):
    a, b = hjorth(x, 50.0), hjorth(x.astype(np.float64), 50.0)
    np.testing.assert_array_equal(a.mobility, b.mobility)
    np.testing.assert_array_equal(a.quality, b.quality)
