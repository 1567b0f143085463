"""The fast paths of core/fast.py equal the straightforward computation.

Reference: the package's original implementation (V expanded onto the fast
time base by zero-order hold, ``n_s x n_v`` broadcast pairs, ranks of the
expanded series; :func:`cell_quantities_reference`) and scipy.stats on the
expanded series.  Property tests cover ties (small integer ranges), flat
channels, ramps, NaN, short windows, missing V, V starting after S, cells
with their own time bases, irregular stamps, wide value ranges (sort
fallback), and the float32 / blocking thresholds of the rank kernel.

Tests of ``cell_quantities`` run with both kernels (``accel``): the numpy
kernel and the compiled one (numba, when installed), which must also agree
with each other bit for bit.
"""

from __future__ import annotations

import contextlib

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from tactile_descriptors_ros.core import fast
from tactile_descriptors_ros.core.aggregation import cell_features
from tactile_descriptors_ros.core.alignment import hold_indices, zero_order_hold
from tactile_descriptors_ros.core.descriptors import Quality, hjorth
from tactile_descriptors_ros.errors import SignalError

FIELDS = ("act_s", "mob_s", "com_s", "act_v", "mob_v", "com_v", "lin", "nonlin")

try:
    import numba  # noqa: F401

    ACCELS = ["numpy", "numba"]
except ImportError:  # the compiled kernel is optional
    ACCELS = ["numpy"]


@contextlib.contextmanager
def using(accel: str):
    """Run with the numpy kernel only, or with the compiled kernel where it applies."""
    fast.set_accelerator(accel)
    try:
        yield
    finally:
        fast.set_accelerator(None)


def _assert_same(fast_out, ref_out, rtol=1e-9, atol=1e-9):
    for name, a, b in zip(FIELDS, fast_out[:8], ref_out[:8]):
        assert a.shape == b.shape, name
        np.testing.assert_allclose(a, b, rtol=rtol, atol=atol, err_msg=name)
    np.testing.assert_array_equal(fast_out[8], ref_out[8], err_msg="quality")


@st.composite
def stamps(draw, n: int, start_max: int = 50, step_max: int = 7, strictly: bool = True) -> np.ndarray:
    """Sorted int64 time stamps, regular or irregular."""
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    start = draw(st.integers(0, start_max))
    if draw(st.booleans()):
        step = draw(st.integers(1, step_max))
        return start + np.arange(n, dtype=np.int64) * step
    lo = 1 if strictly else 0
    gaps = draw(st.lists(st.integers(lo, step_max), min_size=n - 1, max_size=n - 1))
    return start + np.concatenate(([0], np.cumsum(gaps, dtype=np.int64))).astype(np.int64)


@st.composite
def signals(draw, shape: tuple[int, ...], kind: str) -> np.ndarray:
    """Integer counts with many ties, wide integers, or quantised floats (optionally NaN).

    Hypothesis chooses the structure (kind, range, dtype, flat/ramp channels,
    where a NaN goes); the bulk values come from a seeded generator, which
    keeps generation fast.
    """
    size = int(np.prod(shape))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    if kind == "int":
        hi = draw(st.sampled_from([1, 3, 20, 4095]))
        lo = draw(st.sampled_from([0, -hi]))
        dtype = draw(st.sampled_from([np.int16, np.int32, np.int64])) if lo < 0 else \
            draw(st.sampled_from([np.uint16, np.int32, np.int64]))
        arr = rng.integers(lo, hi + 1, shape).astype(dtype)
    elif kind == "wide":
        arr = rng.integers(-(2**40), 2**40, shape, dtype=np.int64)
    else:
        arr = rng.integers(-50, 51, shape).astype(np.float64) * draw(st.sampled_from([0.37, 1e-3, 2.5e4]))
        if size and draw(st.integers(0, 3)) == 0:
            arr.reshape(-1)[draw(st.integers(0, size - 1))] = draw(st.sampled_from([np.nan, np.inf]))
    rows = arr.reshape(-1, shape[-1]) if size else arr
    if size and draw(st.booleans()):
        # a flat channel and a ramp channel (the degenerate cases of eq. 2-5)
        rows[0] = rows[0, 0]
        if rows.shape[0] > 1 and kind == "int":
            rows[1] = np.arange(shape[-1]) % 100
    return arr


@st.composite
def batches(draw):
    n_cells = draw(st.integers(1, 4))
    n_s = draw(st.integers(1, 3))
    n_v = draw(st.integers(1, 4))
    n_fast = draw(st.integers(0, 60))
    n_slow = draw(st.integers(0, 20))
    kind_s = draw(st.sampled_from(["int", "int", "float", "wide"]))
    kind_v = draw(st.sampled_from(["int", "int", "float"]))
    s = draw(signals((n_cells, n_s, n_fast), kind_s))
    v = draw(signals((n_cells, n_v, n_slow), kind_v))
    if draw(st.booleans()):
        ts = draw(stamps(n_fast))
        tv = draw(stamps(n_slow, step_max=25))
    else:  # every cell its own time base (some shared)
        ts = np.stack([draw(stamps(n_fast)) for _ in range(n_cells)]) if n_fast else \
            np.zeros((n_cells, 0), dtype=np.int64)
        tv = np.stack([draw(stamps(n_slow, step_max=25)) for _ in range(n_cells)]) if n_slow else \
            np.zeros((n_cells, 0), dtype=np.int64)
        if n_cells > 1 and draw(st.booleans()):
            ts[1], tv[1] = ts[0], tv[0]
    return s, ts, v, tv


@pytest.mark.parametrize("accel", ACCELS)
@settings(max_examples=100, deadline=None)
@given(batches(), st.sampled_from([100.0, 1000.0]), st.sampled_from([25.0, 250.0]))
def test_cell_quantities_equal_reference(accel, batch, fs_s, fs_v):
    s, ts, v, tv = batch
    with using(accel):
        got = fast.cell_quantities(s, ts, v, tv, fs_s, fs_v)
    _assert_same(got, fast.cell_quantities_reference(s, ts, v, tv, fs_s, fs_v))


@pytest.mark.parametrize("accel", ACCELS)
@settings(max_examples=40, deadline=None)
@given(batches(), st.integers(1, 3))
def test_chunking_does_not_change_results(accel, batch, chunk):
    s, ts, v, tv = batch
    with using(accel):
        whole = fast.cell_quantities(s, ts, v, tv, 1000.0, 250.0)
        chunked = fast.cell_quantities(s, ts, v, tv, 1000.0, 250.0, chunk_samples=chunk)
    _assert_same(chunked, whole, rtol=1e-12, atol=1e-15)


@settings(max_examples=40, deadline=None)
@given(batches())
def test_kernel_thresholds_do_not_change_results(batch):
    """float64 ranks instead of float32, one-row rank blocks, reduceat run sums."""
    s, ts, v, tv = batch
    ref = fast.cell_quantities_reference(s, ts, v, tv, 1000.0, 250.0)
    saved = fast._F32_EXACT, fast._BLOCK_BINS, fast.MAX_SEGMENTS
    try:
        fast._F32_EXACT, fast._BLOCK_BINS, fast.MAX_SEGMENTS = 1, 1, 0
        got = fast.cell_quantities(s, ts, v, tv, 1000.0, 250.0)
    finally:
        fast._F32_EXACT, fast._BLOCK_BINS, fast.MAX_SEGMENTS = saved
    _assert_same(got, ref)


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 3), st.integers(1, 3), st.integers(3, 200), st.integers(2, 30),
       st.sampled_from([1, 7, 4095]), st.data())
def test_held_correlations_match_scipy_on_expanded_series(n_cells, n_s, n_fast, n_slow, hi, data):
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    t_fast = np.sort(rng.choice(10 * n_fast, n_fast, replace=False)).astype(np.int64)
    t_slow = np.sort(rng.choice(10 * n_fast, n_slow, replace=False)).astype(np.int64)
    t_slow[0] = min(t_slow[0], t_fast[0])
    s = rng.integers(0, hi + 1, (n_cells, n_s, n_fast))
    v = rng.integers(0, hi + 1, (n_cells, 2, n_slow)).astype(np.uint16)
    lin, nonlin, _ = fast.held_correlations(s, t_fast, v, t_slow)
    held, valid = zero_order_hold(t_slow, v, t_fast)
    assert valid.all()
    for c in range(n_cells):
        for i in range(n_s):
            for j in range(2):
                a, b = s[c, i], held[c, j].astype(np.int64)
                if np.ptp(a) == 0 or np.ptp(b) == 0:
                    assert lin[c, i, j] == 0 and nonlin[c, i, j] == 0
                    continue
                assert lin[c, i, j] == pytest.approx(stats.pearsonr(a, b)[0], abs=1e-10)
                assert nonlin[c, i, j] == pytest.approx(stats.spearmanr(a, b)[0], abs=1e-10)


@settings(max_examples=80, deadline=None)
@given(st.integers(1, 5), st.integers(0, 80), st.sampled_from([1, 2, 20, 1023, 4095]), st.data())
def test_hjorth_fast_equals_hjorth(rows, n, hi, data):
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    x = rng.integers(-hi, hi + 1, (rows, n)).astype(data.draw(st.sampled_from([np.int16, np.int32, np.int64])))
    if n and data.draw(st.booleans()):
        x[0] = x[0, 0]  # flat
    if n and rows > 1 and data.draw(st.booleans()):
        x[1] = np.arange(n) % (hi + 1)  # ramp: flat derivative
    got, ref = fast.hjorth_fast(x, 1000.0), hjorth(x, 1000.0)
    for a, b in zip(got[:3], ref[:3]):
        np.testing.assert_allclose(a, b, rtol=1e-10, atol=1e-12)
    np.testing.assert_array_equal(got.quality, ref.quality)


def test_hjorth_fast_exact_where_float_cancels():
    """A large offset with a tiny variation: exact integers keep every digit."""
    x = np.array([[2**18 + k % 2 for k in range(1000)]], dtype=np.int64)
    assert fast.exact_integer_ok(1000, 2**18 + 1)
    h = fast.hjorth_fast(x, 1.0)
    assert h.activity[0] == 0.25  # exactly
    # d = +1, -1, ... (500 up, 499 down): var(d) = 1 - 1/999^2
    assert h.mobility[0] == pytest.approx(2.0 * np.sqrt(1.0 - 999.0**-2), rel=1e-15)


@settings(max_examples=80, deadline=None)
@given(st.integers(1, 4), st.integers(1, 40), st.sampled_from(["int", "float"]), st.data())
def test_weighted_ranks_equal_ranks_of_repeated_samples(rows, m, kind, data):
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    x = rng.integers(0, 6, (rows, m))
    x = x if kind == "int" else x * 0.5
    w = rng.integers(1, 6, m).astype(np.int64)
    ranks, ss = fast._weighted_centred_ranks(x, w)
    n = int(w.sum())
    expanded = np.repeat(x, w, axis=1)
    want = 2 * stats.rankdata(expanded, axis=-1) - (n + 1)
    starts = np.concatenate(([0], np.cumsum(w)[:-1]))
    np.testing.assert_array_equal(ranks.copy(), want[:, starts])
    np.testing.assert_allclose(ss, (want**2).sum(axis=1))


@settings(max_examples=80, deadline=None)
@given(st.integers(1, 5), st.integers(1, 60), st.sampled_from([0, 1, 3, 500]), st.integers(1, 9), st.data())
def test_centred_ranks_equal_scipy(rows, n, hi, max_run, data):
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    x = rng.integers(-hi, hi + 1, (rows, n)).astype(np.int16)
    ranks, ss = fast._centred_ranks(x, max_run)
    want = 2 * stats.rankdata(x, axis=-1) - (n + 1)
    np.testing.assert_array_equal(np.asarray(ranks, dtype=np.float64), want)
    np.testing.assert_allclose(ss, (want**2).sum(axis=1))


@settings(max_examples=80, deadline=None)
@given(st.integers(0, 40), st.integers(0, 15), st.data())
def test_hold_runs_match_hold_indices(n_fast, n_slow, data):
    t_fast = data.draw(stamps(n_fast, strictly=False))
    t_slow = data.draw(stamps(n_slow, start_max=80, step_max=20, strictly=False))
    runs = fast.hold_runs(t_slow, t_fast)
    idx = hold_indices(t_slow, t_fast)
    rebuilt = np.full(n_fast, -1, dtype=np.intp)
    for start, k, w in zip(runs.starts, runs.slow_index, runs.weights):
        rebuilt[runs.first + start:runs.first + start + w] = k
    np.testing.assert_array_equal(rebuilt, idx)
    assert runs.n_paired == int((idx >= 0).sum()) == int(runs.weights.sum())
    if runs.segments:
        assert sum(b - a for a, b, _ in runs.segments) == runs.weights.size


@settings(max_examples=40, deadline=None)
@given(st.integers(1, 6), st.integers(3, 300), st.data())
def test_run_sums_equal_reduceat(rows, n, data):
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    t_fast = np.arange(n, dtype=np.int64)
    step = data.draw(st.integers(1, 30))
    offset = data.draw(st.integers(0, step - 1))
    t_slow = np.arange(-offset, n, step, dtype=np.int64)
    runs = fast.hold_runs(t_slow, t_fast)
    x = rng.integers(-9, 10, (rows, runs.n_paired))
    want = np.add.reduceat(x, runs.starts, axis=-1)
    np.testing.assert_array_equal(fast._run_sums(x, runs, "test", np.int64), want)
    np.testing.assert_allclose(fast._run_sums(x.astype(np.float64), runs, "test"), want)


@pytest.mark.parametrize("accel", ACCELS)
def test_cell_features_uses_fast_path_with_same_results(accel):
    rng = np.random.default_rng(3)
    s = rng.integers(-512, 512, (7, 3, 400)).astype(np.int16)
    v = rng.integers(0, 4096, (7, 3, 101)).astype(np.uint16)
    ts = np.arange(400, dtype=np.int64) * 1_000_000
    tv = np.arange(-1, 100, dtype=np.int64) * 4_000_000
    with using(accel):
        feats = cell_features(s, ts, v, tv, 1000.0, 250.0)
    ref = fast.cell_quantities_reference(s, ts, v, tv, 1000.0, 250.0)
    _assert_same([getattr(feats, f) for f in FIELDS] + [feats.quality], ref)


@pytest.mark.parametrize("accel", ACCELS)
def test_degenerate_windows_are_flagged_like_the_reference(accel):
    fast.set_accelerator(accel)
    s = np.array([[[1, 2]]])
    v = np.array([[[3]]])
    got = fast.cell_quantities(s, np.array([0, 1]), v, np.array([0]), 10.0, 10.0)
    assert got[8][0] & Quality.SHORT
    got = fast.cell_quantities(np.zeros((1, 1, 5), dtype=int), np.arange(5), np.zeros((1, 1, 0), dtype=int),
                               np.zeros(0, dtype=np.int64), 10.0, 10.0)
    assert got[8][0] & Quality.SHORT and not got[6].any()
    fast.set_accelerator(None)


@pytest.mark.parametrize("accel", ACCELS)
def test_bad_input_is_a_clear_error(accel):
    fast.set_accelerator(accel)
    with pytest.raises(SignalError, match="same n_cells"):
        fast.cell_quantities(np.zeros((2, 1, 5)), np.arange(5), np.zeros((1, 1, 5)), np.arange(5), 1.0, 1.0)
    with pytest.raises(SignalError, match="time stamps"):
        fast.cell_quantities(np.zeros((1, 1, 5)), np.arange(4), np.zeros((1, 1, 5)), np.arange(5), 1.0, 1.0)
    with pytest.raises(SignalError, match="rate"):
        fast.cell_quantities(np.zeros((1, 1, 5)), np.arange(5), np.zeros((1, 1, 5)), np.arange(5), 0.0, 1.0)
    with pytest.raises(SignalError, match="sorted"):  # integer data: the compiled kernel hands over to numpy
        fast.cell_quantities(np.ones((1, 1, 5), dtype=np.int32), np.array([0, 2, 1, 3, 4]),
                             np.ones((1, 1, 5), dtype=np.int32), np.arange(5), 1.0, 1.0)
    fast.set_accelerator(None)


def test_release_buffers_frees_the_workspace():
    fast.cell_quantities(np.ones((2, 1, 50), dtype=np.int16), np.arange(50), np.ones((2, 1, 10), dtype=np.int16),
                         np.arange(10) * 5, 1.0, 1.0)
    assert fast.release_buffers() > 0
    assert fast.release_buffers() == 0
