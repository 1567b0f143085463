"""The compiled kernel (numba) equals the numpy kernel bit for bit, and stays optional.

``core._numba_kernel`` computes the same exact integer sums as the numpy
kernel of ``core.fast`` and the quantities with the same floating-point
operations, so both give identical arrays (``array_equal``, not
``allclose``).  Without numba, or with ``TACTILE_NO_NUMBA=1``, the core
imports and computes everything with numpy; importing the core never imports
numba (it is loaded on first use).
"""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tactile_descriptors_ros.core import fast

numba = pytest.importorskip("numba")

FIELDS = ("act_s", "mob_s", "com_s", "act_v", "mob_v", "com_v", "lin", "nonlin", "quality")


def _both(s, ts, v, tv, fs_s=1000.0, fs_v=250.0):
    out = {}
    for accel in ("numba", "numpy"):
        fast.set_accelerator(accel)
        try:
            out[accel] = fast.cell_quantities(s, ts, v, tv, fs_s, fs_v)
        finally:
            fast.set_accelerator(None)
    return out["numba"], out["numpy"]


def _identical(a, b):
    for name, x, y in zip(FIELDS, a, b):
        assert x.dtype == y.dtype and x.shape == y.shape, name
        assert np.array_equal(x, y, equal_nan=True), name


@st.composite
def integer_batches(draw):
    """Integer windows: regular runs of 1-30 fast samples per slow sample, or
    irregular stamps; V starting before, with or after S; shared or own time bases."""
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


@settings(max_examples=120, deadline=None)
@given(integer_batches(), st.sampled_from([1000.0, 2200.0]), st.sampled_from([100.0, 250.0]))
def test_compiled_equals_numpy_bit_for_bit(batch, fs_s, fs_v):
    _identical(*_both(*batch, fs_s, fs_v))


@pytest.mark.parametrize("length_s", [0.05, 2.0])
def test_compiled_equals_numpy_on_bench_windows(length_s):
    from tactile_descriptors_ros.core.robot import load_robot
    from tactile_descriptors_ros.perf.bench import _stack_batch, biotac_window, skin_window

    for robot, cells in ((load_robot("shadow_hand"), None), (load_robot("nao"), None)):
        cells = biotac_window(robot, length_s) if robot.name == "shadow_hand" else skin_window(robot, length_s)
        s, ts, v, tv = _stack_batch(cells)
        ct = next(iter(robot.cell_types.values()))
        got, want = _both(s, ts, v, tv, ct.vibration.rate_hz, ct.deformation.rate_hz)
        _identical(got, want)


def test_compiled_hands_over_what_it_cannot_do_exactly():
    rng = np.random.default_rng(0)
    ts, tv = np.arange(40, dtype=np.int64), np.arange(10, dtype=np.int64) * 4
    fast.set_accelerator("numba")
    try:
        kernel = fast._kernel()
        big = rng.integers(-(2**40), 2**40, (2, 2, 40), dtype=np.int64)
        v = rng.integers(0, 50, (2, 3, 10)).astype(np.int64)
        status = kernel.quantities(big, ts[None], v, tv[None], 1.0, 1.0, fast._U_FLAT, 1 << 16)[0]
        assert status == kernel.NOT_EXACT
        status = kernel.quantities(v[:, :, :2], ts[None, :2], v, tv[None], 1.0, 1.0, fast._U_FLAT, 1 << 16)[0]
        assert status == kernel.DEGENERATE
        wide = rng.integers(0, 2**20, (2, 2, 40), dtype=np.int64)
        status = kernel.quantities(wide, ts[None], v, tv[None], 1.0, 1.0, fast._U_FLAT, 1 << 16)[0]
        assert status == kernel.TOO_WIDE
        status = kernel.quantities(v, tv[None, ::-1].copy(), v, tv[None], 1.0, 1.0, fast._U_FLAT, 1 << 16)[0]
        assert status == kernel.UNSORTED
    finally:
        fast.set_accelerator(None)
    # and cell_quantities still answers, through numpy, the same as the reference
    got, want = _both(big, ts, v, tv)
    _identical(got, want)


def test_warm_up_reports_the_accelerator_and_its_load_time():
    info = fast.warm_up()
    assert info["accelerator"] == fast.accelerator()
    assert info["first_call_s"] >= 0.0 and info["import_s"] >= 0.0
    if info["accelerator"] == "numba":
        assert os.path.isdir(info["cache_dir"])


_PROBE = """
import sys, numpy as np
{block}
from tactile_descriptors_ros.core import fast, aggregation, windowing
assert sys.modules.get("numba") is None, "importing the core imported numba"
s = np.ones((2, 1, 50), dtype=np.int32); s[:, :, ::3] = 5
v = np.arange(2 * 2 * 13, dtype=np.int32).reshape(2, 2, 13) % 7
out = fast.cell_quantities(s, np.arange(50), v, np.arange(13) * 4, 1.0, 1.0)
print(fast.accelerator(), float(out[7].sum()))
"""


def _probe(block: str = "", env: dict | None = None) -> tuple[str, float]:
    code = _PROBE.format(block=block)
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                         env={**os.environ, **(env or {})})
    assert res.returncode == 0, res.stderr
    name, value = res.stdout.split()
    return name, float(value)


def test_numba_missing_or_disabled_means_numpy_with_the_same_results():
    blocked = "sys.modules['numba'] = None\nsys.modules['rclpy'] = None"
    assert _probe(blocked)[0] == "numpy"
    off = _probe(env={"TACTILE_NO_NUMBA": "1"})
    on = _probe(env={"TACTILE_NO_NUMBA": ""})
    assert off[0] == "numpy" and on[0] == "numba"
    assert off[1] == on[1]
