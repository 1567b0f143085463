"""The compiled backend is registered by name, optional, and hands the reference what it cannot do exactly.

Without numba, or with ``TACTILE_NO_NUMBA=1``, the core imports and computes
everything with the reference (core/descriptors.py); importing the core never
imports numba (it is loaded on first use).
"""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from tactile_descriptors_ros.core import descriptors, fast
from tactile_descriptors_ros.errors import SignalError

numba = pytest.importorskip("numba")

FLAT = np.uint32(descriptors.Quality.FLAT)  # the flag the kernel sets on a flat signal
FIELDS = ("act_s", "mob_s", "com_s", "act_v", "mob_v", "com_v", "lin", "nonlin", "quality")


def _identical(a, b):
    for name, x, y in zip(FIELDS, a, b):
        assert x.dtype == y.dtype and x.shape == y.shape, name
        assert np.array_equal(x, y, equal_nan=True), name


def test_compiled_hands_over_what_it_cannot_do_exactly():
    rng = np.random.default_rng(0)
    ts, tv = np.arange(40, dtype=np.int64), np.arange(10, dtype=np.int64) * 4
    previous = fast.set_backend("numba")
    try:
        kernel = fast.kernel_module()
        bounds = np.empty((2, 4), dtype=np.int64)
        big = rng.integers(-(2**40), 2**40, (2, 2, 40), dtype=np.int64)
        v = rng.integers(0, 50, (2, 3, 10)).astype(np.int64)
        status = kernel.quantities(big, ts[None], v, tv[None], 1.0, 1.0, FLAT, 1 << 16, bounds)[0]
        assert status == kernel.NOT_EXACT
        status = kernel.quantities(v[:, :, :2], ts[None, :2], v, tv[None], 1.0, 1.0, FLAT, 1 << 16, bounds)[0]
        assert status == kernel.DEGENERATE
        wide = rng.integers(0, 2**20, (2, 2, 40), dtype=np.int64)
        status = kernel.quantities(wide, ts[None], v, tv[None], 1.0, 1.0, FLAT, 1 << 16, bounds)[0]
        assert status == kernel.TOO_WIDE
        status = kernel.quantities(v, tv[None, ::-1].copy(), v, tv[None], 1.0, 1.0, FLAT, 1 << 16, bounds)[0]
        assert status == kernel.UNSORTED
        # and cell_quantities still answers: the reference's own arrays
        _identical(fast.cell_quantities(big, ts, v, tv, 1.0, 1.0), descriptors.cell_quantities(big, ts, v, tv, 1.0, 1.0))
    finally:
        fast.set_backend(None if previous == "numba" else previous)


@pytest.mark.parametrize("stream, cell, same_first, other_equal", [
    ("fast", 1, True, True), ("fast", 1, False, True), ("fast", 2, True, False),
    ("slow", 1, True, True), ("slow", 1, False, False), ("slow", 2, True, False), ("slow", 2, False, True)])
def test_a_cell_stamp_row_that_steps_back_is_handed_to_the_reference(stream, cell, same_first, other_equal):
    """Stamp rows per cell (a window's stacks) are checked as the kernel reaches each new row: a row that steps
    back is found whether its first stamp is the previous cell's or not, and whether the cell's other stream
    is the previous cell's row (its runs then made again for the other stream) or not."""
    rng = np.random.default_rng(1)
    n_cells, n_fast, n_slow = 3, 40, 10
    s = rng.integers(0, 50, (n_cells, 2, n_fast))
    v = rng.integers(0, 50, (n_cells, 3, n_slow))
    ts = np.tile(np.arange(n_fast, dtype=np.int64) * 1_000, (n_cells, 1))
    tv = np.tile(np.arange(n_slow, dtype=np.int64) * 4_000, (n_cells, 1))
    bad, other = (ts, tv) if stream == "fast" else (tv, ts)
    if not other_equal:
        other[cell] += 500  # the cell's other stream on a clock of its own
    if not same_first:
        bad[cell] += 100  # the row on a clock of its own: its first stamp differs too
    bad[cell, [4, 5]] = bad[cell, [5, 4]]  # one step back
    assert (bad[cell, 0] == bad[cell - 1, 0]) == same_first and (np.diff(bad[cell]) < 0).sum() == 1
    previous = fast.set_backend("numba")
    try:
        kernel = fast.kernel_module()
        bounds = np.empty((n_cells, 4), dtype=np.int64)
        status = kernel.quantities(s, ts, v, tv, 1.0, 1.0, FLAT, 1 << 16, bounds)[0]
        assert status == kernel.UNSORTED
        bad[cell] = np.sort(bad[cell])  # the control: the same rows in order are the kernel's
        assert kernel.quantities(s, ts, v, tv, 1.0, 1.0, FLAT, 1 << 16, bounds)[0] == kernel.OK
    finally:
        fast.set_backend(None if previous == "numba" else previous)


def test_backends_are_chosen_by_name():
    assert "numba" in fast.BACKENDS
    previous = fast.set_backend(fast.REFERENCE)
    try:
        assert fast.backend() == fast.REFERENCE and fast.kernel_module() is None
        with pytest.raises(SignalError, match="backend must be one of"):
            fast.set_backend("numpy")
        assert fast.set_backend("numba") == fast.REFERENCE and fast.backend() == "numba"
    finally:
        fast.set_backend(None)
    assert fast.backend() == previous


def test_warm_up_reports_the_backend_and_its_load_time():
    info = fast.warm_up()
    assert info["accelerator"] == fast.backend()
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
print(fast.backend(), repr(float(out[7].sum())))
"""


def _probe(block: str = "", env: dict | None = None) -> tuple[str, float]:
    code = _PROBE.format(block=block)
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                         env={**os.environ, **(env or {})})
    assert res.returncode == 0, res.stderr
    name, value = res.stdout.split()
    return name, float(value)


def test_numba_missing_or_disabled_means_the_reference_with_the_same_results():
    blocked = "sys.modules['numba'] = None\nsys.modules['rclpy'] = None"
    assert _probe(blocked)[0] == fast.REFERENCE
    off = _probe(env={"TACTILE_NO_NUMBA": "1"})
    on = _probe(env={"TACTILE_NO_NUMBA": ""})
    assert off[0] == fast.REFERENCE and on[0] == "numba"
    assert off[1] == pytest.approx(on[1], rel=1e-12, abs=1e-12)
