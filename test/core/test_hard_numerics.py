"""Hard numerical cases for the core descriptors (docs/numerics.md), property-based.

Every test runs with *all* warnings turned into errors, so a NumPy/SciPy
warning leaking out of the core fails the test.  Each case checks the
documented value and flag, and that nothing non-finite comes out unflagged.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from scipy import stats

from tactile_descriptors_ros.core.descriptors import FLAT_RELATIVE_TOLERANCE, Quality, hjorth, pearson, spearman
from tactile_descriptors_ros.errors import SignalError

pytestmark = pytest.mark.filterwarnings("error")

FS_HZ = 1000.0
SETTINGS = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])

SHORT, FLAT, NONFINITE, OVERFLOW = (int(Quality.SHORT), int(Quality.FLAT), int(Quality.NONFINITE),
                                    int(Quality.OVERFLOW))

#: Any float64 except magnitudes >= 2**1023 (see test_samples_near_float64_max_do_not_warn).
any_floats = st.floats(allow_nan=True, allow_infinity=True, width=64).filter(
    lambda v: not np.isfinite(v) or abs(v) < 2.0**1023)
finite_floats = st.floats(min_value=-1e12, max_value=1e12, allow_nan=False, allow_infinity=False)


def _all_finite(h) -> bool:
    return all(np.all(np.isfinite(a)) for a in (h.activity, h.mobility, h.complexity))


# ------------------------------------------------------------------ any input at all


@SETTINGS
@given(hnp.arrays(np.float64, st.integers(0, 8), elements=any_floats))
def test_hjorth_any_short_input_is_finite_and_flagged(x):
    """N = 0..8, any float (NaN, inf, 1e308, subnormal): finite output, documented flags, no warning."""
    h = hjorth(x, FS_HZ)
    assert _all_finite(h)
    q = int(h.quality)
    assert float(h.activity) >= 0 and float(h.mobility) >= 0 and float(h.complexity) >= 0
    if x.size < 3:
        assert q & SHORT and float(h.mobility) == 0 and float(h.complexity) == 0
    if not np.all(np.isfinite(x)):
        assert q & NONFINITE
        assert float(h.activity) == float(h.mobility) == float(h.complexity) == 0.0
    if x.size == 0:
        assert float(h.activity) == 0.0


@SETTINGS
@given(st.integers(0, 8).flatmap(lambda n: st.tuples(
    hnp.arrays(np.float64, n, elements=any_floats), hnp.arrays(np.float64, n, elements=any_floats))))
def test_correlations_any_short_input_are_finite_and_flagged(pair):
    a, b = pair
    for fn in (pearson, spearman):
        r, q = fn(a, b, return_quality=True)
        r, q = float(r), int(q)
        assert np.isfinite(r) and -1.0 <= r <= 1.0
        if a.size < 3:
            assert q & SHORT and r == 0.0
        if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
            assert q & NONFINITE and r == 0.0


# ------------------------------------------------------------------ constants and ramps


@SETTINGS
@given(st.floats(min_value=-1e150, max_value=1e150, allow_nan=False), st.integers(3, 2000),
       st.sampled_from([np.float64, np.float32, np.int64]))
def test_constant_signal_is_flat(c, n, dtype):
    with np.errstate(over="ignore", invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore")  # building the input may overflow float32/int64; not the core's warning
        x = np.full(n, c).astype(dtype)
    assume(np.all(np.isfinite(x)) and (dtype is not np.int64 or abs(c) < 2**62))
    h = hjorth(x, FS_HZ)
    assert int(h.quality) & FLAT
    assert float(h.mobility) == 0.0 and float(h.complexity) == 0.0
    peak = float(np.max(np.abs(x.astype(np.float64)))) if n else 0.0
    assert float(h.activity) <= (FLAT_RELATIVE_TOLERANCE * peak) ** 2
    assert not int(h.quality) & OVERFLOW
    r, qr = pearson(x, np.arange(n, dtype=float), return_quality=True)
    rho, qs = spearman(x, np.arange(n, dtype=float), return_quality=True)
    assert float(r) == float(rho) == 0.0 and int(qr) & FLAT and int(qs) & FLAT


@pytest.mark.parametrize("c", [6.703903964971299e153, 1e200, -1e300])
def test_huge_constant_signal_has_zero_activity(c):
    h = hjorth(np.full(5, c), FS_HZ)
    assert int(h.quality) & FLAT and not int(h.quality) & OVERFLOW
    assert float(h.activity) == 0.0


def _check_ramp(x: np.ndarray, slope: float, n: int) -> None:
    h = hjorth(x, FS_HZ)
    assert int(h.quality) & FLAT
    assert float(h.complexity) == 0.0
    # "Mobility (0 for a ramp)": zero up to the rounding of diff(), 64 eps of the rate
    assert float(h.mobility) <= FLAT_RELATIVE_TOLERANCE * FS_HZ
    assert float(h.activity) == pytest.approx(slope**2 * (n * n - 1) / 12.0, rel=1e-6)


@SETTINGS
@given(st.floats(1e-3, 1e3), st.integers(4, 500), st.sampled_from([np.float64, np.int64]))
def test_ramp_from_zero_has_flat_derivative(slope, n, dtype):
    """A ramp: Activity is its variance, Mobility 0 (documented table), Complexity 0, FLAT."""
    if dtype is np.int64:
        slope = float(max(1, round(slope)))
    _check_ramp((slope * np.arange(n)).astype(dtype), slope, n)


@pytest.mark.parametrize("offset,slope,n", [(1e6, 1e-3, 4), (1e6, 1e-3, 500), (12345.678, 0.01, 50), (1.0, 1e-3, 4)])
def test_ramp_on_dc_offset_has_flat_derivative(offset, slope, n):
    """A slow drift on a DC level (bias drift) is a ramp too: same documented values and flag."""
    _check_ramp(offset + slope * np.arange(n, dtype=np.float64), slope, n)


# ------------------------------------------------------------------ DC offset and dtype


@SETTINGS
@given(st.integers(0, 2**32 - 1), st.integers(64, 3000))
def test_dc_offset_1e6_changes_nothing_beyond_stated_tolerance(seed, n):
    """docs/numerics.md: DC 1e6 changes Activity/Mobility < 1e-8, Complexity < 1e-7 (unit variance)."""
    rng = np.random.default_rng(seed)
    noise = rng.standard_normal(n)
    y = rng.standard_normal(n)
    h0, h1 = hjorth(noise, FS_HZ), hjorth(noise + 1e6, FS_HZ)
    assert int(h0.quality) == int(h1.quality) == 0
    assert float(h1.activity) == pytest.approx(float(h0.activity), rel=1e-8)
    assert float(h1.mobility) == pytest.approx(float(h0.mobility), rel=1e-8)
    assert float(h1.complexity) == pytest.approx(float(h0.complexity), rel=1e-7)
    assert float(pearson(noise + 1e6, y)) == pytest.approx(float(pearson(noise, y)), abs=1e-8)
    assert float(spearman(noise + 1e6, y)) == float(spearman(noise, y))


@SETTINGS
@given(hnp.arrays(np.float32, st.integers(0, 300),
                  elements=st.floats(allow_nan=True, allow_infinity=True, width=32)))
def test_float32_input_equals_float64_of_the_same_values(x32):
    """float32 input is bit-identical to float64 input of the same values (any value, NaN, inf)."""
    h32, h64 = hjorth(x32, FS_HZ), hjorth(x32.astype(np.float64), FS_HZ)
    for a, b in zip(h32, h64):
        np.testing.assert_array_equal(a, b)
    y = np.linspace(-1, 1, x32.size).astype(np.float32) ** 3
    for fn in (pearson, spearman):
        r32, q32 = fn(x32, y, return_quality=True)
        r64, q64 = fn(x32.astype(np.float64), y.astype(np.float64), return_quality=True)
        assert float(r32) == float(r64) and int(q32) == int(q64)


@SETTINGS
@given(st.integers(0, 2**32 - 1))
def test_float32_dc_1e6_with_resolvable_noise_stays_within_quantisation(seed):
    """float32 of 1e6 + noise (std 100): only the float32 rounding (ulp 0.0625) is lost.

    Stated tolerance: Activity within 1e-4 relative, Mobility and Complexity
    within 1e-3, of the float64 values of the unrounded signal.
    """
    rng = np.random.default_rng(seed)
    noise = 100.0 * rng.standard_normal(2000)
    h64 = hjorth(noise, FS_HZ)
    h32 = hjorth((1e6 + noise).astype(np.float32), FS_HZ)
    assert int(h32.quality) == 0
    assert float(h32.activity) == pytest.approx(float(h64.activity), rel=1e-4)
    assert float(h32.mobility) == pytest.approx(float(h64.mobility), rel=1e-3)
    assert float(h32.complexity) == pytest.approx(float(h64.complexity), rel=1e-3)


# ------------------------------------------------------------------ NaN / inf / amplitudes


@SETTINGS
@given(st.integers(0, 2**32 - 1), st.integers(3, 500), st.sampled_from([np.nan, np.inf, -np.inf]), st.data())
def test_one_bad_sample_zeroes_that_signal_only(seed, n, bad, data):
    rng = np.random.default_rng(seed)
    x = rng.standard_normal((3, n))
    row = data.draw(st.integers(0, 2))
    col = data.draw(st.integers(0, n - 1))
    x[row, col] = bad
    h = hjorth(x, FS_HZ)
    assert _all_finite(h)
    assert int(h.quality[row]) & NONFINITE
    assert h.activity[row] == h.mobility[row] == h.complexity[row] == 0.0
    others = [i for i in range(3) if i != row]
    assert not np.any(h.quality[others] & NONFINITE)
    ref = hjorth(x[others], FS_HZ)
    np.testing.assert_array_equal(h.activity[others], ref.activity)
    y = rng.standard_normal(n)
    for fn in (pearson, spearman):
        r, q = fn(x, y, return_quality=True)
        assert r[row] == 0.0 and q[row] & NONFINITE and np.all(np.isfinite(r))


@SETTINGS
@given(st.integers(0, 2**32 - 1), st.integers(8, 1000), st.sampled_from([1e30, 1e-30, 1e150, 1e-150]))
def test_amplitude_scaling_is_exact_up_to_rounding(seed, n, k):
    """Amplitudes 1e30 and 1e-30 (and 1e+-150): Activity scales by k^2, the rest is unchanged."""
    rng = np.random.default_rng(seed)
    x = rng.standard_normal(n)
    y = rng.standard_normal(n) + 0.5 * x
    h, hk = hjorth(x, FS_HZ), hjorth(k * x, FS_HZ)
    assert int(hk.quality) == int(h.quality) == 0
    assert float(hk.activity) == pytest.approx(float(h.activity) * k * k, rel=1e-12)
    assert float(hk.mobility) == pytest.approx(float(h.mobility), rel=1e-12)
    assert float(hk.complexity) == pytest.approx(float(h.complexity), rel=1e-12)
    assert float(pearson(k * x, y)) == pytest.approx(float(pearson(x, y)), abs=1e-13)
    assert float(spearman(k * x, y)) == float(spearman(x, y))


@pytest.mark.parametrize("peak", [2.0**1023, np.finfo(np.float64).max])
def test_samples_near_float64_max_do_not_warn(peak):
    x = np.array([peak, -peak, 0.5 * peak, 0.0])
    h = hjorth(x, FS_HZ)
    assert _all_finite(h) and int(h.quality) & OVERFLOW
    r, q = pearson(x, np.arange(4.0), return_quality=True)
    assert np.isfinite(r) and not int(q) & NONFINITE


def test_activity_beyond_float64_is_clipped_and_flagged():
    x = 1e200 * np.sin(np.arange(100) * 0.3)
    h = hjorth(x, FS_HZ)
    assert int(h.quality) & OVERFLOW
    assert float(h.activity) == np.finfo(np.float64).max
    assert np.isfinite(float(h.mobility)) and float(h.mobility) > 0


# ------------------------------------------------------------------ ties


@SETTINGS
@given(st.integers(0, 2**32 - 1), st.integers(3, 400), st.integers(1, 4),
       st.sampled_from([np.int16, np.int32, np.int64, np.uint16]))
def test_heavy_ties_spearman_matches_scipy(seed, n, levels, dtype):
    """Integer data with 2..5 distinct levels: rho equals scipy's tie-corrected value."""
    rng = np.random.default_rng(seed)
    a = rng.integers(0, levels + 1, n).astype(dtype)
    b = (a.astype(np.int64) + rng.integers(0, 2, n)).astype(dtype)
    rho, q = spearman(a, b, return_quality=True)
    if np.ptp(a) == 0 or np.ptp(b) == 0:
        assert float(rho) == 0.0 and int(q) & FLAT
        return
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref = stats.spearmanr(a, b).statistic
    assert float(rho) == pytest.approx(float(ref), abs=1e-12)
    assert int(q) == 0


@SETTINGS
@given(st.integers(0, 2**32 - 1), st.integers(3, 200), st.integers(0, 2**62), st.booleans())
def test_spearman_on_64bit_integers_across_2_63_matches_scipy(seed, n, small_span, wide):
    """int64 spanning -2^63..2^63-1 and uint64 at and above 2^63: the exact rank correlation.

    scipy ranks int64 exactly; uint64 above 2^63 it converts to float64 (ties
    that are not ties), so the uint64 reference is scipy on the same data
    shifted down by 2^63 into int64, which keeps every rank.
    """
    rng = np.random.default_rng(seed)
    info = np.iinfo(np.int64)
    span = info.max if wide else small_span % 5000
    offset = rng.integers(info.min, info.max - span, endpoint=True) if not wide else info.min
    a = (offset + rng.integers(0, span, n, endpoint=True)).astype(np.int64) if not wide else \
        rng.integers(info.min, info.max, n, endpoint=True, dtype=np.int64)
    if wide:
        a[:2] = info.min, info.max                  # really spans 2^64 - 1
    b = rng.integers(0, 7, n)
    u = (a.view(np.uint64) ^ np.uint64(1 << 63))    # the same order, now 0..2^64-1 (>= 2^63 for a >= 0)
    rho_i, q_i = spearman(a, b, return_quality=True)
    rho_u, q_u = spearman(u, b, return_quality=True)
    assume(np.ptp(b) > 0 and len(np.unique(a)) > 1)
    ref = stats.spearmanr(a, b).statistic
    assert float(rho_i) == pytest.approx(float(ref), abs=1e-12) and int(q_i) == 0
    assert float(rho_u) == pytest.approx(float(ref), abs=1e-12) and int(q_u) == 0


# ------------------------------------------------------------------ shapes


@pytest.mark.parametrize("fn", [pearson, spearman])
def test_mismatched_lengths_raise_signal_error_saying_align(fn):
    with pytest.raises(SignalError, match=r"5 != 7.*align"):
        fn(np.zeros(5), np.zeros(7))


@pytest.mark.parametrize("bad", ["abc", np.array([1 + 2j, 3j, 1]), np.float64(3.0), [None, 1, 2]])
def test_non_numeric_or_scalar_input_raises_signal_error(bad):
    with pytest.raises(SignalError):
        hjorth(bad, FS_HZ)


@pytest.mark.parametrize("fs", [0.0, -1.0, np.nan, np.inf])
def test_impossible_rate_raises_signal_error(fs):
    with pytest.raises(SignalError, match="fs_hz"):
        hjorth(np.arange(10.0), fs)
