"""The descriptor's hot path (core/fast.py, the compiled kernel) equals the reference (core/descriptors.py).

The reference computes the per-cell quantities as the paper states them: V
expanded onto the fast time base by zero-order hold, ``n_s x n_v`` broadcast
pairs, ranks of the expanded series (:func:`descriptors.cell_quantities`);
it is itself checked against scipy.stats on the expanded series.  Property
tests cover ties (small integer ranges), flat channels, ramps, NaN, short
windows, missing V, V starting after S, cells with their own time bases,
irregular stamps, runs of 1 to 30 fast samples per slow one, offsets and wide
value ranges; the compiled backend must agree to rounding and flag exactly
alike, whatever it computes itself or hands to the reference.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from tactile_descriptors_ros.core import descriptors, fast
from tactile_descriptors_ros.core.aggregation import cell_features
from tactile_descriptors_ros.core.alignment import zero_order_hold
from tactile_descriptors_ros.core.descriptors import Quality
from tactile_descriptors_ros.errors import SignalError

FIELDS = ("act_s", "mob_s", "com_s", "act_v", "mob_v", "com_v", "lin", "nonlin")

needs_compiled = pytest.mark.skipif(fast.backend() == fast.REFERENCE,
                                    reason="no compiled backend (numba missing or TACTILE_NO_NUMBA=1)")


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


@st.composite
def integer_batches(draw):
    """Integer windows: regular runs of 1-30 fast samples per slow sample, or
    irregular stamps; V starting before, with or after S; shared or own time bases (also a cell with slow
    stamps of its own beside the others' fast stamps)."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    n_cells, n_s, n_v = draw(st.integers(1, 5)), draw(st.integers(1, 3)), draw(st.integers(1, 4))
    ratio = draw(st.integers(1, 30))
    n_slow = draw(st.integers(3, 40))
    n_fast = n_slow * ratio + draw(st.integers(-2, 2)) * (ratio > 2)
    lead = draw(st.sampled_from([-1, 0, 0, 2]))  # V sample before the window, at its start, or late
    irregular = draw(st.booleans())
    per_cell = draw(st.booleans())
    rows = n_cells if per_cell else 1

    def times():
        tf = np.cumsum(rng.integers(1, 5, (rows, n_fast)), axis=1) if irregular else \
            np.broadcast_to(np.arange(n_fast) * 10, (rows, n_fast))
        tsl = np.broadcast_to((np.arange(n_slow) + lead) * 10 * ratio, (rows, n_slow))
        return np.ascontiguousarray(tf, dtype=np.int64), np.ascontiguousarray(tsl, dtype=np.int64)

    ts, tv = times()
    if rows > 1 and draw(st.booleans()):  # a cell on the others' fast stamps but slow stamps of its own
        tv[-1] += draw(st.integers(1, 10 * ratio - 1))
    elif draw(st.booleans()):  # slow stamps off the fast grid (a clock offset per cell and stream): runs cut at both ends
        tv = tv + rng.integers(1, 10 * ratio, (rows, 1))
    hi = draw(st.sampled_from([1, 3, 40, 511, 4095]))
    lo = draw(st.sampled_from([0, -hi]))
    dtype = draw(st.sampled_from([np.int16, np.int32, np.int64, np.uint16] if lo == 0 else
                                 [np.int16, np.int32, np.int64]))
    s = rng.integers(lo, hi + 1, (n_cells, n_s, n_fast)).astype(dtype)
    v = rng.integers(0, draw(st.sampled_from([2, 50, 4096])), (n_cells, n_v, n_slow)).astype(dtype)
    if draw(st.booleans()):
        s[0, 0] = s[0, 0, 0]  # flat channel
        v[-1, -1] = 7
    if draw(st.booleans()):
        s += np.asarray(draw(st.sampled_from([256, 2000])), dtype=dtype)  # offsets (gravity, baselines)
    return s, (ts if per_cell else ts[0]), v, (tv if per_cell else tv[0])



@needs_compiled
@settings(max_examples=100, deadline=None)
@given(batches(), st.sampled_from([100.0, 1000.0]), st.sampled_from([25.0, 250.0]))
def test_cell_quantities_equal_reference(batch, fs_s, fs_v):
    s, ts, v, tv = batch
    _assert_same(fast.cell_quantities(s, ts, v, tv, fs_s, fs_v), descriptors.cell_quantities(s, ts, v, tv, fs_s, fs_v))


@needs_compiled
@settings(max_examples=120, deadline=None)
@given(integer_batches(), st.sampled_from([1000.0, 2200.0]), st.sampled_from([100.0, 250.0]))
def test_compiled_integer_windows_equal_reference(batch, fs_s, fs_v):
    """The windows the compiled kernel computes itself: regular and irregular runs, offsets."""
    s, ts, v, tv = batch
    _assert_same(fast.cell_quantities(s, ts, v, tv, fs_s, fs_v), descriptors.cell_quantities(s, ts, v, tv, fs_s, fs_v))


@needs_compiled
@settings(max_examples=60, deadline=None)
@given(integer_batches())
def test_bounded_quantities_are_the_quantities_and_each_cells_bounds(batch):
    s, ts, v, tv = batch
    done = fast.cell_quantities_bounded(s, ts, v, tv, 1000.0, 250.0)
    if done is None:  # the kernel hands this batch to the reference (too few pairs)
        assert descriptors.cell_quantities(s, ts, v, tv, 1000.0, 250.0)[8].any()
        return
    quantities, bounds = done
    for got, want in zip(quantities, fast.cell_quantities(s, ts, v, tv, 1000.0, 250.0)):
        np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(bounds, np.stack([s.min(axis=(1, 2)), s.max(axis=(1, 2)),
                                                    v.min(axis=(1, 2)), v.max(axis=(1, 2))], axis=1))


@needs_compiled
@pytest.mark.parametrize("length_s", [0.05, 2.0])
def test_bench_windows_equal_reference(length_s):
    from tactile_descriptors_ros.core.robot import load_robot
    from tactile_descriptors_ros.sim.synthetic import biotac_window, skin_window

    for robot in (load_robot("shadow_hand"), load_robot("nao")):
        cells = biotac_window(robot, length_s) if robot.name == "shadow_hand" else skin_window(robot, length_s)
        ids = sorted(cells)
        s, v = np.stack([cells[i].vibration for i in ids]), np.stack([cells[i].deformation for i in ids])
        ts, tv = cells[ids[0]].vibration_t_ns, cells[ids[0]].deformation_t_ns
        ct = next(iter(robot.cell_types.values()))
        fs_s, fs_v = ct.vibration.rate_hz, ct.deformation.rate_hz
        _assert_same(fast.cell_quantities(s, ts, v, tv, fs_s, fs_v),
                     descriptors.cell_quantities(s, ts, v, tv, fs_s, fs_v))


@needs_compiled
@settings(max_examples=300, deadline=None)
@given(st.integers(0, 80), st.integers(1, 25), st.booleans(), st.booleans(), st.data())
def test_compiled_hold_runs_are_the_zero_order_hold(n_fast, n_slow, fast_ties, slow_ties, data):
    """The kernel's runs of held slow samples: which slow sample every fast sample holds, as
    :func:`zero_order_hold` says, for regular stamps (its guess of a run's end) and irregular ones, ties,
    slow samples before, among and after the fast ones, and slow samples that no fast sample holds."""
    kernel = fast.kernel_module()
    t_fast = data.draw(stamps(n_fast, step_max=4, strictly=not fast_ties))
    t_slow = data.draw(stamps(n_slow, start_max=120, step_max=25, strictly=not slow_ties)) - data.draw(
        st.integers(0, 60))
    starts, slow_index, weights = (np.full(n_slow, -1, dtype=np.int64) for _ in range(3))
    first, n_runs = kernel._hold_runs(t_slow, t_fast, starts, slow_index, weights)
    held = np.repeat(slow_index[:n_runs], weights[:n_runs])
    _, valid = zero_order_hold(t_slow, np.zeros(n_slow), t_fast)
    want = np.searchsorted(t_slow, t_fast, side="right") - 1  # the last slow sample at or before each fast one
    assert first == (int(np.argmax(valid)) if valid.any() else n_fast)
    np.testing.assert_array_equal(held, want[first:])
    np.testing.assert_array_equal(starts[:n_runs], np.r_[0, np.cumsum(weights[:n_runs - 1])] if n_runs else [])
    assert (weights[:n_runs] > 0).all() and (np.diff(slow_index[:n_runs]) > 0).all()


@needs_compiled
def test_cells_with_equal_and_different_stamp_rows_are_each_computed_on_their_own_stamps():
    """Stamp rows per cell (a window's stacks), equal to the previous cell's or not: every cell's quantities
    are those of the cell alone (the kernel reuses the previous cell's runs only for equal rows)."""
    rng = np.random.default_rng(3)
    n_cells, n_fast, n_slow = 7, 400, 100
    s = rng.integers(0, 300, (n_cells, 3, n_fast))
    v = rng.integers(0, 300, (n_cells, 2, n_slow))
    regular = np.arange(n_fast, dtype=np.int64) * 1_000_000, np.arange(n_slow, dtype=np.int64) * 4_000_000
    shifted = regular[0], regular[1] + 1_500_000  # other runs: V a sample and a half later
    irregular = np.cumsum(rng.integers(1, 3, n_fast)) * 1_000_000, regular[1]
    rows = [regular, regular, shifted, shifted, regular, irregular, irregular]
    ts = np.stack([r[0] for r in rows])
    tv = np.stack([r[1] for r in rows])
    together = fast.cell_quantities(s, ts, v, tv, 1000.0, 250.0)
    for c in range(n_cells):
        alone = fast.cell_quantities(s[c:c + 1], ts[c], v[c:c + 1], tv[c], 1000.0, 250.0)
        for name, a, b in zip((*FIELDS, "quality"), together, alone):
            np.testing.assert_array_equal(a[c:c + 1], b, err_msg=f"cell {c}: {name}")
    assert not np.array_equal(together[6][1], together[6][2])  # the shifted runs do change the correlations


@needs_compiled
@pytest.mark.parametrize("robot_name", ["nao", "shadow_hand"])
def test_cells_with_a_clock_per_stream_equal_reference(robot_name):
    """The bench's window with every cell's fast and slow stamps moved by offsets of their own, as the node
    stamps them (a clock per cell and stream): the slow samples fall between the fast ones, so each cell's
    first and last runs are shorter than the others, and the window starts with fast samples that hold none."""
    from tactile_descriptors_ros.core.robot import load_robot
    from tactile_descriptors_ros.sim.synthetic import biotac_window, skin_window

    robot = load_robot(robot_name)
    cells = biotac_window(robot, 2.0) if robot_name == "shadow_hand" else skin_window(robot, 2.0)
    ids = sorted(cells)
    rng = np.random.default_rng(5)
    s, v = np.stack([cells[i].vibration for i in ids]), np.stack([cells[i].deformation for i in ids])
    ts = cells[ids[0]].vibration_t_ns[None, :] + rng.integers(-400_000, 400_000, (len(ids), 1))
    tv = cells[ids[0]].deformation_t_ns[None, :] + rng.integers(-400_000, 400_000, (len(ids), 1))
    ct = next(iter(robot.cell_types.values()))
    fs_s, fs_v = ct.vibration.rate_hz, ct.deformation.rate_hz
    _assert_same(fast.cell_quantities(s, ts, v, tv, fs_s, fs_v), descriptors.cell_quantities(s, ts, v, tv, fs_s, fs_v),
                 rtol=1e-12, atol=1e-12)


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 3), st.integers(1, 3), st.integers(3, 200), st.integers(2, 30),
       st.sampled_from([1, 7, 4095]), st.data())
def test_reference_correlations_match_scipy_on_expanded_series(n_cells, n_s, n_fast, n_slow, hi, data):
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1)))
    t_fast = np.sort(rng.choice(10 * n_fast, n_fast, replace=False)).astype(np.int64)
    t_slow = np.sort(rng.choice(10 * n_fast, n_slow, replace=False)).astype(np.int64)
    t_slow[0] = min(t_slow[0], t_fast[0])
    s = rng.integers(0, hi + 1, (n_cells, n_s, n_fast))
    v = rng.integers(0, hi + 1, (n_cells, 2, n_slow)).astype(np.uint16)
    lin, nonlin, _ = descriptors.held_correlations(s, t_fast, v, t_slow)
    got = fast.cell_quantities(s, t_fast, v, t_slow, 1.0, 1.0)
    held, valid = zero_order_hold(t_slow, v, t_fast)
    assert valid.all()
    for c in range(n_cells):
        for i in range(n_s):
            for j in range(2):
                a, b = s[c, i], held[c, j].astype(np.int64)
                if np.ptp(a) == 0 or np.ptp(b) == 0:
                    assert lin[c, i, j] == 0 and nonlin[c, i, j] == 0
                    assert got[6][c, i, j] == 0 and got[7][c, i, j] == 0
                    continue
                assert lin[c, i, j] == pytest.approx(stats.pearsonr(a, b)[0], abs=1e-10)
                assert nonlin[c, i, j] == pytest.approx(stats.spearmanr(a, b)[0], abs=1e-10)
                assert got[6][c, i, j] == pytest.approx(stats.pearsonr(a, b)[0], abs=1e-10)
                assert got[7][c, i, j] == pytest.approx(stats.spearmanr(a, b)[0], abs=1e-10)


def test_exact_where_float_cancels():
    """A large offset with a tiny variation: exact integer sums keep every digit."""
    x = np.array([[[2**18 + k % 2 for k in range(1000)]]], dtype=np.int64)
    v = np.array([[[2**18 + k % 3 for k in range(250)]]], dtype=np.int64)
    assert fast.exact_integer_ok(1000, 2**18 + 2)
    got = fast.cell_quantities(x, np.arange(1000) * 4, v, np.arange(250) * 16, 1.0, 0.25)
    assert got[0][0, 0] == 0.25  # exactly
    # d = +1, -1, ... (500 up, 499 down): var(d) = 1 - 1/999^2
    assert got[1][0, 0] == pytest.approx(2.0 * np.sqrt(1.0 - 999.0**-2), rel=1e-12)


def test_cell_features_uses_the_hot_path_with_reference_results():
    rng = np.random.default_rng(3)
    s = rng.integers(-512, 512, (7, 3, 400)).astype(np.int16)
    v = rng.integers(0, 4096, (7, 3, 101)).astype(np.uint16)
    ts = np.arange(400, dtype=np.int64) * 1_000_000
    tv = np.arange(-1, 100, dtype=np.int64) * 4_000_000
    feats = cell_features(s, ts, v, tv, 1000.0, 250.0)
    ref = descriptors.cell_quantities(s, ts, v, tv, 1000.0, 250.0)
    _assert_same([getattr(feats, f) for f in FIELDS] + [feats.quality], ref)


def test_degenerate_windows_are_flagged_like_the_reference():
    s = np.array([[[1, 2]]])
    v = np.array([[[3]]])
    got = fast.cell_quantities(s, np.array([0, 1]), v, np.array([0]), 10.0, 10.0)
    assert got[8][0] & Quality.SHORT
    got = fast.cell_quantities(np.zeros((1, 1, 5), dtype=int), np.arange(5), np.zeros((1, 1, 0), dtype=int),
                               np.zeros(0, dtype=np.int64), 10.0, 10.0)
    assert got[8][0] & Quality.SHORT and not got[6].any()


def test_bad_input_is_a_clear_error():
    with pytest.raises(SignalError, match="same n_cells"):
        fast.cell_quantities(np.zeros((2, 1, 5)), np.arange(5), np.zeros((1, 1, 5)), np.arange(5), 1.0, 1.0)
    with pytest.raises(SignalError, match="time stamps"):
        fast.cell_quantities(np.zeros((1, 1, 5)), np.arange(4), np.zeros((1, 1, 5)), np.arange(5), 1.0, 1.0)
    with pytest.raises(SignalError, match="rate"):
        fast.cell_quantities(np.zeros((1, 1, 5)), np.arange(5), np.zeros((1, 1, 5)), np.arange(5), 0.0, 1.0)
    with pytest.raises(SignalError, match="sorted"):  # integer data: the compiled kernel hands over to the reference
        fast.cell_quantities(np.ones((1, 1, 5), dtype=np.int32), np.array([0, 2, 1, 3, 4]),
                             np.ones((1, 1, 5), dtype=np.int32), np.arange(5), 1.0, 1.0)


def test_release_buffers_frees_the_pool():
    a = fast.scratch("test.a", (3, 50), np.int32)
    assert a.shape == (3, 50) and fast.scratch("test.a", (2, 10), np.int32).base is a.base
    assert fast.release_buffers() >= a.nbytes
    assert fast.release_buffers() == 0


# --------------------------------------------------------- feature groups' compiled passes
def _exact_central_moments(row) -> tuple[float, float, float]:
    from fractions import Fraction

    v = [int(t) for t in row]
    mu = Fraction(sum(v), len(v))
    return tuple(float(sum((Fraction(t) - mu) ** k for t in v) / len(v)) for k in (2, 3, 4))


@needs_compiled
@settings(max_examples=40, deadline=None)
@given(st.integers(1, 400), st.integers(1, 5), st.sampled_from([1, 3, 4095, 2**20, 2**40, 2**62]),
       st.sampled_from([np.int32, np.int64]), st.integers(0, 2**32 - 1))
def test_compiled_central_moments_are_the_exact_moments_rounded(n, rows, hi, dtype, seed):
    """Integer rows: the kernel's m2, m3, m4 within a few roundings of the exact rational moments,
    from exact integer sums or (values too wide for them) from two float passes."""
    if dtype == np.int32:
        hi = min(hi, 2**31 - 1)
    rng = np.random.default_rng(seed)
    x = rng.integers(-hi, hi, (rows, n), dtype=np.int64, endpoint=True).astype(dtype)
    x[0] = x[0, 0]  # a flat row
    out = np.empty((rows, 5))
    fast.kernel_module().central_moments(x, out)
    for r in range(rows):
        want = _exact_central_moments(x[r])
        scale = max(abs(float(x[r].astype(np.float64).mean())), float(np.abs(x[r] - x[r].mean()).max()), 1.0)
        narrow = float(n) * (2.0 * hi) ** 4 < 2.0**62  # exact integer sums: a few roundings of well-scaled terms
        tol = 1e-14 if narrow else 1e-9  # two float passes over the row
        for k, w in enumerate(want):
            assert abs(out[r, k + 1] - w) <= tol * scale ** (k + 2) + tol * abs(w), (r, k)
        assert out[r, 0] == x[r].astype(np.float64).sum() / n or abs(out[r, 0] - x[r].mean()) <= 1e-12 * scale
        assert out[r, 4] == float(np.abs(x[r].astype(np.float64)).max())
    # a flat row: exactly no variance from exact sums; within the flatness tolerance of moments() otherwise
    assert out[0, 1] == 0.0 if float(n) * (2.0 * hi) ** 4 < 2.0**62 else out[0, 1] <= 1e-12 * out[0, 4] ** 2


@needs_compiled
def test_compiled_feature_passes_equal_numpy():
    """bands (spectral moments of each band) and statistics (moments) through the kernel = the numpy formulation."""
    from tactile_descriptors_ros.core.features import band_hjorth, moments

    rng = np.random.default_rng(11)
    x = rng.integers(-300, 300, (7, 3, 2000)).astype(np.int32)
    x[:, 2] += 256
    previous = fast.set_backend(fast.REFERENCE)
    try:
        want_bands, want_moments = band_hjorth(x, 1000.0), moments(x)
    finally:
        fast.set_backend(None if previous != fast.REFERENCE else previous)
    np.testing.assert_allclose(band_hjorth(x, 1000.0), want_bands, rtol=1e-12)
    for got, want in zip(moments(x), want_moments):
        np.testing.assert_allclose(got, want, rtol=1e-11, atol=1e-12)
