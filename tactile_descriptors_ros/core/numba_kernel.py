"""The compiled backend of :mod:`.fast`: the descriptor's hot path for integer sensor data (numba).

Per cell, while its samples are in the cache, one loop per signal row: the
exact integer moments of the Hjorth parameters (row sum, sum of squares,
lag-1 and lag-2 products, end samples; eq. 1-3 need no difference array),
the counting ranks (histogram of the row's values, prefix sum: twice the
centred average rank ``2 r - (n + 1)`` is an integer), the run sums of the
samples and of their ranks over the zero-order-hold runs of V (held V is
piecewise constant, so every sum over the expanded series is a sum over
runs, and the held V's ranks are ranks weighted by the run lengths), and
the cross sums with every held V channel (eq. 4-5).  Every sum is an exact
integer (checked against 2**53 before use), so the quantities differ from
the reference (:func:`.descriptors.cell_quantities`) by rounding only.
What this module cannot compute exactly it reports by a status code, and
:func:`.fast.cell_quantities` hands it to the reference.

This module imports numba; :mod:`.fast` imports it lazily, only when the
backend is first used (``TACTILE_NO_NUMBA=1`` disables it).  Compiled
code is cached on disk (``cache=True``) in :data:`CACHE_DIR`, filled at
set-up (``make setup`` runs :func:`~.fast.main`) and found by every node
afterwards:

* ``$NUMBA_CACHE_DIR/tactile_descriptors_ros`` when the user set it;
* else ``<venv>/var/cache/tactile_descriptors_ros/numba`` in a virtual
  environment (one cache per set of installed libraries);
* else ``$XDG_CACHE_HOME`` (``~/.cache``) ``/tactile_descriptors_ros/numba``.

numba names a cache folder after the source file's directory, so a copy of
the package at another path (colcon's ``build/`` or ``install/``, a wheel)
would compile again for about 30 s.  This module's functions are therefore
located by :class:`_KernelCacheLocator`: one folder for any path, and
numba's own staleness check (a hash of the source file's contents, plus
numba's version and the CPU) decides whether the cached code fits.  numba
has no public hook for that (``NUMBA_CACHE_LOCATOR_CLASSES`` replaces every
locator, also other packages'), so the locator is put first in numba's list
of locators; if that list ever moves, numba's default locators serve, only
path-dependent.
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

import numba
import numpy as np

__all__ = ["quantities", "cell_bounds", "central_moments", "power_spectrum", "band_moments", "rocket_ppv",
           "runs_in_order", "append_runs", "add_part_runs", "explore_runs", "trim_rows", "cut_rows", "decode_can_rows",
           "track_forward", "skin_stamp_add", "skin_part_cdr", "skin_part_cdr_bytes", "SKIN_PART_CDR_PLAN", "CACHE_DIR",
           "PATH_INDEPENDENT_CACHE", "OK", "NOT_EXACT", "DEGENERATE",
           "UNSORTED", "TOO_WIDE", "CAN_OK", "CAN_REMOTE_OR_ERROR", "CAN_FOREIGN", "CAN_UNKNOWN_MODALITY",
           "CAN_BAD_LENGTH", "CAN_UNKNOWN_CELL", "CAN_BAD_PAYLOAD"]


def _writable_dir(path: Path) -> bool:
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError:
        return False
    return os.access(path, os.W_OK)


def _cache_dir() -> str:
    """Where compiled code is cached (see the module docstring)."""
    if os.environ.get("NUMBA_CACHE_DIR"):
        candidates = [Path(os.environ["NUMBA_CACHE_DIR"]) / "tactile_descriptors_ros"]
    else:
        candidates = []
        if sys.prefix != sys.base_prefix:  # a virtual environment
            candidates.append(Path(sys.prefix) / "var" / "cache" / "tactile_descriptors_ros" / "numba")
        xdg = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
        candidates.append(Path(xdg) / "tactile_descriptors_ros" / "numba")
    uid = os.getuid() if hasattr(os, "getuid") else 0
    candidates.append(Path(tempfile.gettempdir()) / f"tactile_numba_cache_{uid}")
    for path in candidates:
        if _writable_dir(path):
            return str(path)
    return str(candidates[-1])


#: Directory of the on-disk cache of compiled code.
CACHE_DIR: str = _cache_dir()
_THIS_FILE = Path(__file__).resolve()


def _install_locator() -> bool:
    """Put :class:`_KernelCacheLocator` first in numba's locators; False when numba's internals differ."""
    try:
        from numba.core import caching
        from numba.core.caching import _CacheLocator, _SourceFileBackedLocatorMixin
    except ImportError:
        return False
    impl = getattr(caching, "CacheImpl", None) or getattr(caching, "_CacheImpl", None)  # renamed in numba 0.6x

    class _KernelCacheLocator(_SourceFileBackedLocatorMixin, _CacheLocator):
        """This module's functions, cached in :data:`CACHE_DIR` whatever the install path."""

        def __init__(self, py_func, py_file) -> None:
            self._py_file = py_file
            self._lineno = py_func.__code__.co_firstlineno

        def get_cache_path(self) -> str:
            return CACHE_DIR

        @classmethod
        def from_function(cls, py_func, py_file):
            try:
                if Path(py_file).resolve() != _THIS_FILE:
                    return None  # another package's function: numba's own locators
            except OSError:
                return None
            return super().from_function(py_func, py_file)

    locators = getattr(impl, "_locator_classes", None)
    if not isinstance(locators, list):
        return False
    if not any(c.__name__ == "_KernelCacheLocator" for c in locators):
        locators.insert(0, _KernelCacheLocator)
    return True


#: True when the cache does not depend on where the package is installed.
PATH_INDEPENDENT_CACHE: bool = _install_locator()
if not PATH_INDEPENDENT_CACHE:
    numba.config.CACHE_DIR = CACHE_DIR

#: Status codes of :func:`quantities` (anything but OK: the reference computes the batch).
OK, NOT_EXACT, DEGENERATE, UNSORTED, TOO_WIDE = 0, 1, 2, 3, 4

_F64_EXACT = float(2**53)
_I64_SAFE = float(2**62)

_jit = numba.njit(cache=True, nogil=True, boundscheck=False)
# Sums of exact integers (every partial sum below 2**53, which is checked
# before they are used) are the same in any order: reassociation (fastmath)
# lets LLVM vectorise them without changing a bit.
#
# Sums of floats that are not exact integers change bits when reassociated;
# where a few roundings do not matter (sums of a power spectrum, all terms
# >= 0) 'reassoc' alone lets them vectorise, without fastmath's other
# assumptions (no NaN, no inf: a window with a non-finite sample must give
# a non-finite value, which the caller drops and reports).
_jit_reassoc = numba.njit(cache=True, nogil=True, boundscheck=False, fastmath={"reassoc"})
#
# Indexing: numba wraps a negative signed index around (x[-1] is the last
# element), a branch per access that LLVM cannot prove away for x[i - 1] or
# table[a - lo]; it then gathers where it could load, or does not vectorise.
# Lagged rows are therefore read through shifted slices (x[1:], x[:n - 1])
# and computed indices, never negative here, are cast to np.uint64.
_jit_exact = numba.njit(cache=True, nogil=True, boundscheck=False, fastmath=True)


@_jit
def cell_bounds(x, lo, hi):  # pragma: no cover - compiled
    """Minimum and maximum of each row of ``x`` (rows, n >= 1) into ``lo``, ``hi``."""
    for r in range(x.shape[0]):
        a = x[r, 0]
        b = x[r, 0]
        for i in range(x.shape[1]):
            a = min(a, x[r, i])
            b = max(b, x[r, i])
        lo[r] = a
        hi[r] = b


@_jit_exact
def _moments_row(x, out):  # pragma: no cover - compiled
    """Sum, sum of squares, lag-1 and lag-2 products, x[0], x[1], x[n-2], x[n-1], min, max (n >= 3).

    Two loops that vectorise: the sum, squares and bounds, then both lag products over shifted slices.
    """
    n = x.shape[0]
    s1 = 0.0
    q = 0.0
    lo = x[0]
    hi = x[0]
    for i in range(n):
        a = float(x[i])
        s1 += a
        q += a * a
        lo = min(lo, x[i])
        hi = max(hi, x[i])
    a2 = x[2:]
    b1 = x[1:n - 1]
    b2 = x[:n - 2]
    r1 = float(x[1]) * float(x[0])
    r2 = 0.0
    for i in range(n - 2):
        a = float(a2[i])
        r1 += a * float(b1[i])
        r2 += a * float(b2[i])
    out[0] = s1
    out[1] = q
    out[2] = r1
    out[3] = r2
    out[4] = x[0]
    out[5] = x[1]
    out[6] = x[n - 2]
    out[7] = x[n - 1]
    out[8] = lo
    out[9] = hi


@_jit_exact
def _dot(a, b):  # pragma: no cover - compiled
    acc = 0.0
    for k in range(a.shape[0]):
        acc += a[k] * b[k]
    return acc


@_jit_exact
def _sums(a):  # pragma: no cover - compiled
    s1 = 0.0
    q = 0.0
    for k in range(a.shape[0]):
        x = float(a[k])
        s1 += x
        q += x * x
    return s1, q


@_jit
def _exact_ok(n, peak):  # pragma: no cover - compiled
    """:func:`~.fast.exact_integer_ok` (the same float operations)."""
    p = 4.0 * max(peak, 1.0)
    return n * p * p < _F64_EXACT and float(n) * n * p * p < _I64_SAFE


@_jit
def _sorted(t):  # pragma: no cover - compiled
    """Whether a stamp row never steps back (one pass without a branch over shifted slices, which
    vectorises; sorted rows are the common case)."""
    n = t.shape[0]
    if n < 2:
        return True
    later = t[1:]
    earlier = t[:n - 1]
    back = np.int64(0)
    for i in range(n - 1):
        back += later[i] < earlier[i]
    return back == 0


@_jit
def _same_rows(a, b):  # pragma: no cover - compiled
    """Whether two stamp rows of equal length are equal, element by element (one pass without a branch,
    which vectorises; equal rows are the common case).  Rows whose first stamps differ (each cell on its
    own clock) are told apart without the pass."""
    if a.shape[0] and a[0] != b[0]:
        return False
    d = np.int64(0)
    for i in range(a.shape[0]):
        d |= a[i] ^ b[i]
    return d == 0


@_jit
def _hold_runs(t_slow, t_fast, starts, slow_index, weights):  # pragma: no cover - compiled
    """The zero-order hold of slow samples on sorted fast stamps as runs; returns (first, n_runs).

    Fast sample ``p`` holds slow sample ``j``, the last with ``t_slow[j] <= t_fast[p]``
    (as :func:`.alignment.zero_order_hold`); ``first`` is the first fast sample that holds one.
    Run ``k`` is the fast samples ``first + starts[k]`` onwards, ``weights[k]`` of them, holding
    ``slow_index[k]``; slow samples that no fast sample holds have no run.  One step per slow
    sample: a run's end is first guessed to be as long as the run before (regular stamps) and
    checked by two comparisons; a wrong guess is found by scanning, as a merge would.
    """
    n_fast = t_fast.shape[0]
    n_slow = t_slow.shape[0]
    p = 0
    while p < n_fast and t_fast[p] < t_slow[0]:
        p += 1
    first = p
    n_runs = 0
    last = 0
    for j in range(n_slow):
        if p >= n_fast:
            break
        if j + 1 == n_slow:
            e = n_fast
        else:
            nxt = t_slow[j + 1]
            e = p + last
            # the guess holds when every fast sample before it is earlier than the next slow sample
            # and the one at it (if any) is not
            if not (e <= n_fast and (e == p or t_fast[np.uint64(e - 1)] < nxt)
                    and (e == n_fast or t_fast[np.uint64(e)] >= nxt)):
                e = p
                while e < n_fast and t_fast[e] < nxt:
                    e += 1
        if e > p:
            starts[n_runs] = p - first
            slow_index[n_runs] = j
            weights[n_runs] = e - p
            n_runs += 1
            last = e - p
            p = e
    return first, n_runs


@_jit
def _short_runs(row, lo, table, length, n_runs, run_x, run_r):  # pragma: no cover - compiled
    """Run sums of samples and of their ranks for runs of 1 to 4 samples, unrolled."""
    if length == 1:
        for k in range(n_runs):
            a0 = row[k]
            run_x[k] = a0
            run_r[k] = table[np.uint64(a0 - lo)]
    elif length == 2:
        for k in range(n_runs):
            a0 = row[2 * k]
            a1 = row[2 * k + 1]
            run_x[k] = np.int64(a0) + a1
            run_r[k] = table[np.uint64(a0 - lo)] + table[np.uint64(a1 - lo)]
    elif length == 3:
        for k in range(n_runs):
            a0 = row[3 * k]
            a1 = row[3 * k + 1]
            a2 = row[3 * k + 2]
            run_x[k] = np.int64(a0) + a1 + a2
            run_r[k] = table[np.uint64(a0 - lo)] + table[np.uint64(a1 - lo)] + table[np.uint64(a2 - lo)]
    else:
        for k in range(n_runs):
            a0 = row[4 * k]
            a1 = row[4 * k + 1]
            a2 = row[4 * k + 2]
            a3 = row[4 * k + 3]
            run_x[k] = np.int64(a0) + a1 + a2 + a3
            run_r[k] = (table[np.uint64(a0 - lo)] + table[np.uint64(a1 - lo)]
                        + table[np.uint64(a2 - lo)] + table[np.uint64(a3 - lo)])


@_jit
def _long_runs(row, lo, table, starts, weights, k0, k1, run_x, run_r):  # pragma: no cover - compiled
    """Run sums of samples and of their ranks for runs ``k0`` to ``k1 - 1`` of any length."""
    for k in range(k0, k1):
        p0 = starts[k]
        acc = 0
        accr = 0
        for p in range(p0, p0 + weights[k]):
            a = row[p]
            acc += a
            accr += table[np.uint64(a - lo)]
        run_x[k] = acc
        run_r[k] = accr


@_jit
def _hjorth_row(n, fs, mom):  # pragma: no cover - compiled
    """Hjorth parameters (eq. 1-3) from exact row moments; returns (A, M, C, flat).

    With ``d`` the first and ``dd`` the second difference, ``n^2 var(x)``,
    ``(n-1)^2 var(d)`` and ``(n-2)^2 var(dd)`` are exact integers from the
    sum, the sum of squares, the lag-1 and lag-2 products and the end samples.
    For integer data a non-zero variance is at least ``1/n^2``, far above the
    reference's flatness tolerance: flat means exactly zero here."""
    s1 = np.int64(mom[0])
    q = np.int64(mom[1])
    r1 = np.int64(mom[2])
    r2 = np.int64(mom[3])
    x0 = np.int64(mom[4])
    x1 = np.int64(mom[5])
    xm = np.int64(mom[6])
    xl = np.int64(mom[7])
    num_x = n * q - s1 * s1
    sd = xl - x0
    sd2 = 2 * q - x0 * x0 - xl * xl - 2 * r1
    num_d = (n - 1) * sd2 - sd * sd
    sdd = (xl - xm) - (x1 - x0)
    sdd2 = ((q - x0 * x0 - x1 * x1) + 4 * (q - x0 * x0 - xl * xl) + (q - xm * xm - xl * xl)
            - 4 * (r1 - x0 * x1) - 4 * (r1 - xm * xl) + 2 * r2)
    num_dd = (n - 2) * sdd2 - sdd * sdd
    var_x = float(num_x) / float(n * n)
    var_d = float(num_d) / float((n - 1) * (n - 1))
    var_dd = float(num_dd) / float((n - 2) * (n - 2))
    flat = num_x == 0
    flat_d = num_d == 0
    mob_x = 0.0 if flat else np.sqrt(var_d / var_x)
    mob_d = 0.0 if flat_d else np.sqrt(var_dd / var_d)
    com = 0.0 if (flat or flat_d) else mob_d / mob_x
    return var_x, mob_x * fs, com, flat or flat_d


@_jit
def quantities(s, ts, v, tv, fs_s, fs_v, flat_flag, max_span, bounds):  # pragma: no cover - compiled
    """Every per-cell quantity of eq. 1-5 for integer cells, exactly; see :func:`.descriptors.cell_quantities`.

    Parameters
    ----------
    s : (n_cells, n_s, n_fast) int32 or int64 array
    ts : (1 or n_cells, n_fast) int64 array
        Fast stamps, shared by all cells (one row) or per cell.
    v : (n_cells, n_v, n_slow) int32 or int64 array
    tv : (1 or n_cells, n_slow) int64 array
    fs_s, fs_v : float
    flat_flag : uint32
        The quality flag of a flat channel or pair.
    max_span : int
        Largest value span of a row ranked by counting.
    bounds : (n_cells, 4) int64 array
        Filled with each cell's smallest and largest S value, then V value
        (valid when status is OK): the saturation check needs no pass of its own.

    Returns
    -------
    status : int
        :data:`OK`, or why the reference must compute the batch (:data:`NOT_EXACT`:
        sums would pass 2**53; :data:`DEGENERATE`: fewer than 3 samples or
        pairs; :data:`UNSORTED` stamps; :data:`TOO_WIDE` value span).
    act_s, mob_s, com_s, act_v, mob_v, com_v, lin, nonlin, quality : arrays
        As :func:`.descriptors.cell_quantities` (valid when status is OK).

    Notes
    -----
    Per row, one loop each for the moments, the value histogram and the run
    sums; ranks are ``2 r - (n + 1)`` from the histogram's prefix sums (ties
    get average ranks), held V is ranked with the run lengths as weights.
    Every sum is an exact integer (checked before use): the quantities
    differ from the reference's by the rounding of the last operations.
    """
    n_cells, n_s, n_fast = s.shape
    n_v, n_slow = v.shape[1], v.shape[2]
    act_s = np.zeros((n_cells, n_s))
    mob_s = np.zeros((n_cells, n_s))
    com_s = np.zeros((n_cells, n_s))
    act_v = np.zeros((n_cells, n_v))
    mob_v = np.zeros((n_cells, n_v))
    com_v = np.zeros((n_cells, n_v))
    lin = np.zeros((n_cells, n_s, n_v))
    nonlin = np.zeros((n_cells, n_s, n_v))
    quality = np.zeros(n_cells, dtype=np.uint32)
    if n_cells == 0 or n_s == 0 or n_v == 0 or n_fast < 3 or n_slow < 3:
        return DEGENERATE, act_s, mob_s, com_s, act_v, mob_v, com_v, lin, nonlin, quality
    if float(n_fast) ** 3 >= _F64_EXACT / 2:
        return NOT_EXACT, act_s, mob_s, com_s, act_v, mob_v, com_v, lin, nonlin, quality
    # Shared stamp rows are checked here; a window's per-cell rows as the loop reaches each new one (below),
    # while it is in the cache for its hold runs: a row equal to the previous cell's was checked with it.
    if (ts.shape[0] == 1 and not _sorted(ts[0])) or (tv.shape[0] == 1 and not _sorted(tv[0])):
        return UNSORTED, act_s, mob_s, com_s, act_v, mob_v, com_v, lin, nonlin, quality
    # One pass per cell while its samples are in the cache: moments (and the
    # exactness check on the peaks so far: the peaks only grow, so this is the
    # check on all cells), hold runs, ranks, run sums, cross sums, quantities.
    mom_s = np.empty((n_cells, n_s, 10))
    mom_v = np.empty((n_cells, n_v, 10))
    peak_s = 0.0
    peak_v = 0.0
    m = n_slow  # each run holds another slow sample: at most n_slow runs
    starts = np.empty(m, dtype=np.int64)
    slow_index = np.empty(m, dtype=np.int64)
    weights = np.empty(m, dtype=np.int64)
    counts = np.zeros(1024, dtype=np.int64)
    table = np.zeros(1024, dtype=np.int64)
    counts4 = np.zeros(4096, dtype=np.int32)
    vk = np.empty((n_v, m), dtype=np.int64)
    vf = np.empty((n_v, m))
    rv = np.empty((n_v, m))
    wf = np.empty(m)
    wrv = np.empty(m)
    run_x = np.empty(m)
    run_r = np.empty(m)
    sums_v = np.empty((n_v, 3))
    first = 0
    n_runs = 0
    n = 0
    length = 0
    regular = False
    mid_regular = False
    mid = 0
    uniform = False
    contiguous = False
    for c in range(n_cells):
        # the hold runs of the previous cell serve while its stamp rows are this cell's too (a window's
        # stacks hold a stamp row per cell, mostly equal ones: comparing costs a tenth of the merge)
        if c == 0 or (ts.shape[0] > 1 and not _same_rows(ts[c], ts[c - 1])) \
                or (tv.shape[0] > 1 and not _same_rows(tv[c], tv[c - 1])):
            t_fast = ts[min(c, ts.shape[0] - 1)]
            t_slow = tv[min(c, tv.shape[0] - 1)]
            if (ts.shape[0] > 1 and not _sorted(t_fast)) or (tv.shape[0] > 1 and not _sorted(t_slow)):
                return UNSORTED, act_s, mob_s, com_s, act_v, mob_v, com_v, lin, nonlin, quality
            first, n_runs = _hold_runs(t_slow, t_fast, starts, slow_index, weights)
            n = n_fast - first
            if n < 3:
                return DEGENERATE, act_s, mob_s, com_s, act_v, mob_v, com_v, lin, nonlin, quality
            length = weights[0]
            uniform = True
            contiguous = True
            for k in range(n_runs):
                wf[k] = weights[k]
                if weights[k] != length:
                    uniform = False
                if slow_index[k] != slow_index[0] + k:
                    contiguous = False
            regular = uniform and length <= 4
            # runs of one length but the first and the last (a cell whose slow stamps are not on its fast
            # grid: the window cuts a run at each end), the inner ones unrolled as the regular runs
            mid = weights[1] if n_runs > 2 else 0
            mid_regular = not regular and 1 <= mid <= 4
            for k in range(1, n_runs - 1):
                if weights[k] != mid:
                    mid_regular = False
        for i in range(n_s):
            _moments_row(s[c, i], mom_s[c, i])
            peak_s = max(peak_s, abs(mom_s[c, i, 8]), abs(mom_s[c, i, 9]))
        for j in range(n_v):
            _moments_row(v[c, j], mom_v[c, j])
            peak_v = max(peak_v, abs(mom_v[c, j, 8]), abs(mom_v[c, j, 9]))
        bounds[c, 0] = np.int64(mom_s[c, 0, 8])
        bounds[c, 1] = np.int64(mom_s[c, 0, 9])
        bounds[c, 2] = np.int64(mom_v[c, 0, 8])
        bounds[c, 3] = np.int64(mom_v[c, 0, 9])
        for i in range(1, n_s):
            bounds[c, 0] = min(bounds[c, 0], np.int64(mom_s[c, i, 8]))
            bounds[c, 1] = max(bounds[c, 1], np.int64(mom_s[c, i, 9]))
        for j in range(1, n_v):
            bounds[c, 2] = min(bounds[c, 2], np.int64(mom_v[c, j, 8]))
            bounds[c, 3] = max(bounds[c, 3], np.int64(mom_v[c, j, 9]))
        if not (_exact_ok(n_fast, max(peak_s, peak_v)) and _exact_ok(n_slow, peak_v)):
            return NOT_EXACT, act_s, mob_s, com_s, act_v, mob_v, com_v, lin, nonlin, quality
        qc = np.uint32(0)
        # Hjorth parameters of every channel
        for i in range(n_s):
            a, m, cx, flat = _hjorth_row(n_fast, fs_s, mom_s[c, i])
            act_s[c, i] = a
            mob_s[c, i] = m
            com_s[c, i] = cx
            if flat:
                qc |= flat_flag
        for j in range(n_v):
            a, m, cx, flat = _hjorth_row(n_slow, fs_v, mom_v[c, j])
            act_v[c, j] = a
            mob_v[c, j] = m
            com_v[c, j] = cx
            if flat:
                qc |= flat_flag
        # V rows: the held samples, ranked with run-length weights
        for j in range(n_v):
            vrow = v[c, j]
            vkj = vk[j]
            vfj = vf[j]
            rvj = rv[j]
            if contiguous:  # run k holds slow sample s0 + k (every slow sample in the window)
                seg = vrow[slow_index[0]:slow_index[0] + n_runs]
                for k in range(n_runs):
                    vkj[k] = seg[k]
            else:
                for k in range(n_runs):
                    vkj[k] = vrow[slow_index[k]]
            lo = vkj[0]
            hi = lo
            for k in range(n_runs):
                a = vkj[k]
                vfj[k] = a
                lo = min(lo, a)
                hi = max(hi, a)
            span = hi - lo + 1
            if span > max_span:
                return TOO_WIDE, act_s, mob_s, com_s, act_v, mob_v, com_v, lin, nonlin, quality
            if span > counts.shape[0]:
                counts = np.zeros(span, dtype=np.int64)
                table = np.zeros(span, dtype=np.int64)
            counts[:span] = 0
            if uniform:  # every run as long: counts of values, times the length
                for k in range(n_runs):
                    counts[np.uint64(vkj[k] - lo)] += 1
                cum = 0
                for b in range(span):
                    cnt = counts[b] * length
                    cum += cnt
                    table[b] = 2 * cum - cnt - n
            else:
                for k in range(n_runs):
                    counts[np.uint64(vkj[k] - lo)] += weights[k]
                cum = 0
                for b in range(span):
                    cnt = counts[b]
                    cum += cnt
                    table[b] = 2 * cum - cnt - n
            for k in range(n_runs):
                rvj[k] = table[np.uint64(vkj[k] - lo)]
            for k in range(n_runs):
                wrv[k] = wf[k] * vfj[k]
            sums_v[j, 0] = _dot(wf[:n_runs], vfj[:n_runs])
            sums_v[j, 1] = _dot(wrv[:n_runs], vfj[:n_runs])
            for k in range(n_runs):
                wrv[k] = wf[k] * rvj[k]
            sums_v[j, 2] = _dot(wrv[:n_runs], rvj[:n_runs])
        # S rows: counting ranks, run sums of samples and of ranks, cross sums
        for i in range(n_s):
            row = s[c, i, first:]
            # the whole row's bounds serve for its samples from ``first`` on too (values absent from them
            # count 0 and are never looked up); only a span too wide for them takes the samples' own
            if first == 0 or np.int64(mom_s[c, i, 9]) - np.int64(mom_s[c, i, 8]) < max_span:
                lo = np.int64(mom_s[c, i, 8])
                hi = np.int64(mom_s[c, i, 9])
            else:
                lo = np.int64(row[0])
                hi = lo
                for p in range(n):
                    lo = min(lo, np.int64(row[p]))
                    hi = max(hi, np.int64(row[p]))
            span = hi - lo + 1
            if span > max_span:
                return TOO_WIDE, act_s, mob_s, com_s, act_v, mob_v, com_v, lin, nonlin, quality
            if span > counts.shape[0]:
                counts = np.zeros(span, dtype=np.int64)
                table = np.zeros(span, dtype=np.int64)
            if 2 * span > counts4.shape[0]:
                counts4 = np.zeros(2 * span, dtype=np.int32)
            ca = counts4[:span]
            cb = counts4[span:2 * span]
            ca[:] = 0
            cb[:] = 0
            # even and odd samples counted apart: a value repeated in consecutive samples (a slowly
            # varying signal) does not wait for its own previous increment
            n2 = n // 2
            for q in range(n2):
                ca[np.uint64(row[2 * q] - lo)] += 1
                cb[np.uint64(row[2 * q + 1] - lo)] += 1
            if n % 2:
                ca[np.uint64(row[n - 1] - lo)] += 1
            cum = 0
            rss = 0.0
            for b in range(span):
                cnt = np.int64(ca[b]) + cb[b]
                cum += cnt
                t = 2 * cum - cnt - n
                table[b] = t
                rss += float(cnt * t * t)
            if regular:
                _short_runs(row, lo, table, length, n_runs, run_x, run_r)
            elif mid_regular:
                _long_runs(row, lo, table, starts, weights, 0, 1, run_x, run_r)
                _short_runs(row[weights[0]:], lo, table, mid, n_runs - 2, run_x[1:], run_r[1:])
                _long_runs(row, lo, table, starts, weights, n_runs - 1, n_runs, run_x, run_r)
            else:
                _long_runs(row, lo, table, starts, weights, 0, n_runs, run_x, run_r)
            if first == 0:
                s1 = np.int64(mom_s[c, i, 0])
                q = np.int64(mom_s[c, i, 1])
            elif first < n:  # the whole row's sums less those of the samples before ``first`` (exact integers)
                hs1, hq = _sums(s[c, i, :first])
                s1 = np.int64(mom_s[c, i, 0]) - np.int64(hs1)
                q = np.int64(mom_s[c, i, 1]) - np.int64(hq)
            else:
                fs1, fq = _sums(row)
                s1 = np.int64(fs1)
                q = np.int64(fq)
            den_s = float(n * q - s1 * s1)
            for j in range(n_v):
                # Pearson (eq. 4) from exact sums over the runs
                v1 = np.int64(sums_v[j, 0])
                v2 = np.int64(sums_v[j, 1])
                den_v = float(n * v2 - v1 * v1)
                num = n * np.int64(_dot(run_x[:n_runs], vf[j, :n_runs])) - s1 * v1
                den = np.sqrt(den_s) * np.sqrt(den_v)
                r = float(num) / den if den > 0 else 0.0
                flat_pair = den_s == 0 or den_v == 0
                if flat_pair:
                    r = 0.0
                lin[c, i, j] = min(max(r, -1.0), 1.0)
                # Spearman (eq. 5): Pearson of the centred ranks
                rvv = sums_v[j, 2]
                rden = np.sqrt(rss) * np.sqrt(rvv)
                rho = _dot(run_r[:n_runs], rv[j, :n_runs]) / rden if rden > 0 else 0.0
                rflat = rss == 0 or rvv == 0
                if rflat:
                    rho = 0.0
                nonlin[c, i, j] = min(max(rho, -1.0), 1.0)
                if flat_pair or rflat:
                    qc |= flat_flag
        quality[c] = qc
    return OK, act_s, mob_s, com_s, act_v, mob_v, com_v, lin, nonlin, quality


@_jit
def _two_pass_moments(row, out):  # pragma: no cover - compiled
    """:func:`central_moments` of one row in float: the mean, then sums of the centred powers, in row order."""
    n = row.shape[0]
    s = 0.0
    peak = 0.0
    for i in range(n):
        v = float(row[i])
        s += v
        peak = max(peak, abs(v))
    mean = s / n
    s2 = 0.0
    s3 = 0.0
    s4 = 0.0
    for i in range(n):
        d = float(row[i]) - mean
        d2 = d * d
        s2 += d2
        s3 += d2 * d
        s4 += d2 * d2
    out[0] = mean
    out[1] = s2 / n
    out[2] = s3 / n
    out[3] = s4 / n
    out[4] = peak


@_jit_exact
def _row_sum_bounds(row):  # pragma: no cover - compiled
    """Exact sum (int64), smallest and largest value of an integer row."""
    s1 = np.int64(0)
    lo = np.int64(row[0])
    hi = lo
    for i in range(row.shape[0]):
        a = np.int64(row[i])
        s1 += a
        lo = min(lo, a)
        hi = max(hi, a)
    return s1, lo, hi


@_jit_exact
def _shifted_power_sums(row, x0):  # pragma: no cover - compiled
    """Sums of ``y``, ``y^2``, ``y^3``, ``y^4`` with ``y = row - x0``, exact int64 (bounds checked by the caller)."""
    s1 = np.int64(0)
    s2 = np.int64(0)
    s3 = np.int64(0)
    s4 = np.int64(0)
    for i in range(row.shape[0]):
        y = np.int64(row[i]) - x0
        y2 = y * y
        s1 += y
        s2 += y2
        s3 += y2 * y
        s4 += y2 * y2
    return s1, s2, s3, s4


@_jit
def central_moments(x, out):  # pragma: no cover - compiled
    """Per row of integer ``x`` (rows, n >= 1): mean, m2, m3, m4 (biased central moments), max |x| into ``out``.

    From exact integer sums: the row's sum and bounds, then the sums of the
    powers 1-4 of ``y = x - x0`` with ``x0`` the mean rounded to an
    integer, exact in int64 while ``n (max |y|)^4 < 2**62``; with
    ``d = sum(y) / n`` (``|d| <= 1/2``) the central moments are
    ``m2 = S2/n - d^2``, ``m3 = S3/n - 3 d S2/n + 2 d^3``,
    ``m4 = S4/n - 4 d S3/n + 6 d^2 S2/n - 3 d^4``: a few roundings of
    well-scaled terms, no sum of 2,000 rounded terms, and loops that
    vectorise (the ``statistics`` group's skewness and kurtosis,
    :func:`.features.moments`).  Rows whose powers would not be exact take
    the two float passes (mean, then centred powers).
    """
    n = x.shape[1]
    for r in range(x.shape[0]):
        row = x[r]
        total, lo, hi = _row_sum_bounds(row)
        x0 = (2 * total + n) // (2 * n)  # the mean rounded (floor division: half up)
        span = float(max(hi - x0, x0 - lo))
        if float(n) * span * span * span * span >= _I64_SAFE:
            _two_pass_moments(row, out[r])
            continue
        s1, s2, s3, s4 = _shifted_power_sums(row, x0)
        d = float(s1) / n
        a2 = float(s2) / n
        a3 = float(s3) / n
        a4 = float(s4) / n
        dd = d * d
        out[r, 0] = float(total) / n
        out[r, 1] = a2 - dd
        out[r, 2] = a3 - 3.0 * d * a2 + 2.0 * dd * d
        out[r, 3] = a4 - 4.0 * d * a3 + 6.0 * dd * a2 - 3.0 * dd * dd
        out[r, 4] = float(max(abs(lo), abs(hi)))


@_jit
def power_spectrum(xf, w, out):  # pragma: no cover - compiled
    """``out[r, k] = (re^2 + im^2) w[k]`` of complex rows ``xf`` seen as interleaved float64 (rows, 2 m); ``out[r, 0] = 0``.

    One pass over the spectrum with the operations of
    :func:`.features.power_spectrum`'s numpy formulation (square, add, scale:
    the same bits), instead of three passes and a temporary.
    """
    m = out.shape[1]
    for r in range(xf.shape[0]):
        out[r, 0] = 0.0
        for k in range(1, m):
            a = xf[r, 2 * k]
            b = xf[r, 2 * k + 1]
            out[r, k] = (a * a + b * b) * w[k]


@_jit_reassoc
def band_moments(p, g, lo, hi, out):  # pragma: no cover - compiled
    """Spectral moments of bands: ``out[r, b] = sum over k in [lo[b], hi[b]) of p[r, k] (1, g[k], g[k]^2)``.

    ``p`` (rows, bins) is a power spectrum and ``g`` the first difference's
    gain per bin: the ``bands`` group's Hjorth parameters of each band
    (:func:`.features.band_hjorth`) in one pass over the spectrum.
    """
    for r in range(p.shape[0]):
        pr = p[r]
        for b in range(lo.shape[0]):
            pb = pr[lo[b]:hi[b]]
            gb = g[lo[b]:hi[b]]
            s0 = 0.0
            s1 = 0.0
            s2 = 0.0
            for k in range(pb.shape[0]):
                pk = pb[k]
                pg = pk * gb[k]
                s0 += pk
                s1 += pg
                s2 += pg * gb[k]
            out[r, b, 0] = s0
            out[r, b, 1] = s1
            out[r, b, 2] = s2


@_jit
def rocket_ppv(x, dilations, per_dilation, channels_per_combination, channel_indices, biases, indices,
               out):  # pragma: no cover - compiled
    """MiniRocket's PPV features (:func:`.rocket.transform`): ``out[i, f] = mean_t [C_t > b_f]``.

    Per series and dilation, the nine shifted copies of every channel (zeros
    past the ends) and their sum are formed once; a kernel's output is then,
    for the channels of its combination, ``-sum + 3 (three taps)``, counted
    against its biases over the whole series (even ``dilation index +
    kernel index``) or the positions where the kernel lies inside it (odd).
    The operations of :func:`.rocket.convolve` in another order: integer
    counts give the same outputs exactly (floats: up to rounding).
    """
    n_series, n_ch, n_t = x.shape
    n_kernels = indices.shape[0]
    shifted = np.empty((9, n_ch, n_t))
    total = np.empty((n_ch, n_t))
    c = np.empty(n_t)
    for i in range(n_series):
        f = 0
        c0 = 0
        comb = 0
        for j in range(dilations.shape[0]):
            d = dilations[j]
            pad = 4 * d
            for k in range(9):
                s = (k - 4) * d
                for ch in range(n_ch):
                    for t in range(n_t):
                        u = t + s
                        shifted[k, ch, t] = x[i, ch, u] if 0 <= u < n_t else 0.0
            for ch in range(n_ch):
                for t in range(n_t):
                    acc = 0.0
                    for k in range(9):
                        acc += shifted[k, ch, t]
                    total[ch, t] = acc
            for kern in range(n_kernels):
                a = indices[kern, 0]
                b = indices[kern, 1]
                g = indices[kern, 2]
                nc = channels_per_combination[comb]
                for t in range(n_t):
                    c[t] = 0.0
                for q in range(nc):
                    ch = channel_indices[c0 + q]
                    for t in range(n_t):
                        c[t] += 3.0 * (shifted[a, ch, t] + shifted[b, ch, t] + shifted[g, ch, t]) - total[ch, t]
                lo = 0
                hi = n_t
                if (j + kern) % 2 == 1:
                    lo = pad
                    hi = n_t - pad
                m = per_dilation[j]
                for q in range(m):
                    bias = biases[f + q]
                    count = 0
                    for t in range(lo, hi):
                        if c[t] > bias:
                            count += 1
                    out[i, f + q] = count / (hi - lo) if hi > lo else 0.0
                f += m
                c0 += nc
                comb += 1


# ------------------------------------------------------------------ a body part's message, converted
@_jit
def skin_part_arrays(a_count, f_count, tare, ax, ay, az, a_off, force, f_off, stamp_ns, n_per_count,
                     invalid_accel, invalid_count, proximity, temperature_c, extra_codes):  # pragma: no cover
    """A ``SkinPartFrames``' sample arrays as :func:`..streams.skin_parts.skin_part_chunk` makes them, one pass each.

    ``a_count``, ``f_count`` (uint32, one per run), ``tare`` (float64, three per run), the accelerometer axes
    ``ax``, ``ay``, ``az`` (int16), ``a_off`` and ``f_off`` (int64 offsets from ``stamp_ns``) and ``force``
    (uint16, three sensors per sample) are the message's fields.  Returns ``ok`` (False, and empty arrays,
    when a length disagrees with the runs' counts: the caller's checks then name the fault), the counts as
    int64, the accelerometer as (3, n) int32 with its validity and stamps, the force sensors as (3, m) int32
    with their validity, the contact force in newtons and their stamps.  The force is numpy's sum of
    the three tared sensors in sensor order divided by three, times ``n_per_count``, NaN where a sensor is
    ``invalid_count``: the same operations in the same order, so the same bits.  ``extra_codes`` asks for
    extra rows, one per code, over the force samples: 0 the ``proximity`` counts (NaN where
    ``invalid_count``, or everywhere when the message has none), 1 each run's ``temperature_c``; they are
    returned last, (len(extra_codes), m) float64.
    """
    n = a_count.shape[0]
    n_a = 0
    n_f = 0
    for r in range(n):
        n_a += np.int64(a_count[r])
        n_f += np.int64(f_count[r])
    ok = (f_count.shape[0] == n and tare.shape[0] == 3 * n and ax.shape[0] == n_a and ay.shape[0] == n_a
          and az.shape[0] == n_a and a_off.shape[0] == n_a and force.shape[0] == 3 * n_f and f_off.shape[0] == n_f
          and temperature_c.shape[0] == n and (proximity.shape[0] == 0 or proximity.shape[0] == n_f))
    if not ok:
        n, n_a, n_f = 0, 0, 0
    a_cnt = np.empty(n, dtype=np.int64)
    f_cnt = np.empty(n, dtype=np.int64)
    acc = np.empty((3, n_a), dtype=np.int32)
    vib_ok = np.empty(n_a, dtype=np.bool_)
    t_a = np.empty(n_a, dtype=np.int64)
    forces = np.empty((3, n_f), dtype=np.int32)
    f_ok = np.empty(n_f, dtype=np.bool_)
    force_n = np.empty(n_f)
    t_f = np.empty(n_f, dtype=np.int64)
    extra = np.empty((extra_codes.shape[0], n_f))
    for r in range(n):
        a_cnt[r] = a_count[r]
        f_cnt[r] = f_count[r]
    for i in range(n_a):
        x = ax[i]
        y = ay[i]
        z = az[i]
        acc[0, i] = x
        acc[1, i] = y
        acc[2, i] = z
        vib_ok[i] = x != invalid_accel and y != invalid_accel and z != invalid_accel
        t_a[i] = a_off[i] + stamp_ns
    k = 0
    for r in range(n):
        c0 = tare[3 * r]
        c1 = tare[3 * r + 1]
        c2 = tare[3 * r + 2]
        for _ in range(f_cnt[r]):
            s0 = force[3 * k]
            s1 = force[3 * k + 1]
            s2 = force[3 * k + 2]
            forces[0, k] = s0
            forces[1, k] = s1
            forces[2, k] = s2
            good = s0 != invalid_count and s1 != invalid_count and s2 != invalid_count
            f_ok[k] = good
            if good:
                force_n[k] = ((np.float64(s0) - c0) + (np.float64(s1) - c1) + (np.float64(s2) - c2)) / 3.0 \
                    * n_per_count
            else:
                force_n[k] = np.nan
            t_f[k] = f_off[k] + stamp_ns
            for e in range(extra_codes.shape[0]):
                if extra_codes[e] == 1:
                    extra[e, k] = temperature_c[r]
                elif proximity.shape[0] and proximity[k] != invalid_count:
                    extra[e, k] = np.float64(proximity[k])
                else:
                    extra[e, k] = np.nan
            k += 1
    return ok, a_cnt, f_cnt, acc, vib_ok, t_a, forces, f_ok, force_n, t_f, extra


# ------------------------------------------------------------------ a body part's message, read from its CDR bytes
#: Where a ``SkinPartFrames``' fields lie in its CDR payload, after the header's stamp, in order: a sequence's
#: element size in bytes (1: a string), or -8 for a float64 field (see :func:`skin_part_cdr`).
SKIN_PART_CDR_PLAN = (1, 1, 4, 4, 4, 4, 8, 8, 4, 2, 2, 2, 8, -8, 2, 8, -8, 2, -8)


@_jit
def _cdr_align(pos, size):  # pragma: no cover - compiled
    """``pos`` moved up to the next multiple of ``size`` counted from the payload (after the 4-byte header)."""
    r = (pos - 4) % size
    return pos if r == 0 else pos + size - r


@_jit
def _cdr_u32(buf, pos):  # pragma: no cover - compiled
    """The little-endian uint32 at ``pos``."""
    return (np.int64(buf[pos]) | (np.int64(buf[pos + 1]) << 8) | (np.int64(buf[pos + 2]) << 16)
            | (np.int64(buf[pos + 3]) << 24))


@_jit
def _cdr_seq_at(pos, n, size):  # pragma: no cover - compiled
    """Where a sequence of ``n`` elements of ``size`` bytes written at ``pos`` puts its length, its first element
    and its end (its elements aligned only when there are any, as Fast CDR writes them)."""
    at = _cdr_align(pos, 4)
    first = at + 4
    if n:
        first = _cdr_align(first, size)
    return at, first, first + n * size


@_jit
def skin_part_cdr(buf):  # pragma: no cover - compiled
    """A ``SkinPartFrames`` read from its CDR bytes: where each field lies, and its arrays as views of ``buf``.

    ``buf`` (uint8) is the serialised message as rmw hands it: a 4-byte encapsulation header, then the
    fields in order, each aligned to its size counted from the end of the header, a sequence (or string)
    as its uint32 length then its elements (aligned only when there are any), a string's length counting
    its closing NUL.  :data:`SKIN_PART_CDR_PLAN` lists the fields after the stamp.  Only little-endian
    plain CDR (header ``00 01``, what Fast DDS writes) is read.  Every length is checked against the
    buffer's size before it is used, so bytes of any kind never read outside it.

    Returns ``ok`` (False: not little-endian CDR, or a length past the end), the stamp's ``sec`` and
    ``nanosec``, each field's byte offset and length (``starts``, ``counts``: elements, a string's
    bytes with its NUL), then the 14 arrays as views of ``buf`` (empty where not ``ok``) and the three
    float64 fields, in the message's order.  The views are aligned where the payload is aligned to 8
    bytes in memory.
    """
    n_buf = buf.shape[0]
    n_plan = len(SKIN_PART_CDR_PLAN)
    starts = np.zeros(n_plan, dtype=np.int64)
    counts = np.zeros(n_plan, dtype=np.int64)
    scalars = np.zeros(3)
    ok = n_buf >= 12 and buf[0] == 0 and buf[1] == 1
    sec = np.int64(0)
    nanosec = np.int64(0)
    if ok:
        sec = _cdr_u32(buf, 4)
        if sec >= 2**31:
            sec -= 2**32
        nanosec = _cdr_u32(buf, 8)
    pos = 12
    k = 0
    for i in range(n_plan):
        if not ok:
            break
        size = SKIN_PART_CDR_PLAN[i]
        if size < 0:
            pos = _cdr_align(pos, 8)
            if pos + 8 > n_buf:
                ok = False
                break
            starts[i] = pos
            counts[i] = 1
            scalars[k] = buf[pos:pos + 8].view(np.float64)[0]
            k += 1
            pos += 8
            continue
        at = _cdr_align(pos, 4)
        if at + 4 > n_buf:
            ok = False
            break
        n = _cdr_u32(buf, at)
        _, first, pos = _cdr_seq_at(at, n, size)
        if pos > n_buf:
            ok = False
            break
        starts[i] = first
        counts[i] = n
    if not ok:
        starts[:] = 0
        counts[:] = 0
    return (ok, sec, nanosec, starts, counts,
            buf[starts[2]:starts[2] + 4 * counts[2]].view(np.uint32),
            buf[starts[3]:starts[3] + 4 * counts[3]].view(np.uint32),
            buf[starts[4]:starts[4] + 4 * counts[4]].view(np.uint32),
            buf[starts[5]:starts[5] + 4 * counts[5]].view(np.uint32),
            buf[starts[6]:starts[6] + 8 * counts[6]].view(np.float64),
            buf[starts[7]:starts[7] + 8 * counts[7]].view(np.float64),
            buf[starts[8]:starts[8] + 4 * counts[8]].view(np.uint32),
            buf[starts[9]:starts[9] + 2 * counts[9]].view(np.int16),
            buf[starts[10]:starts[10] + 2 * counts[10]].view(np.int16),
            buf[starts[11]:starts[11] + 2 * counts[11]].view(np.int16),
            buf[starts[12]:starts[12] + 8 * counts[12]].view(np.int64),
            scalars[0],
            buf[starts[14]:starts[14] + 2 * counts[14]].view(np.uint16),
            buf[starts[15]:starts[15] + 8 * counts[15]].view(np.int64),
            scalars[1],
            buf[starts[17]:starts[17] + 2 * counts[17]].view(np.uint16),
            scalars[2])


@_jit
def _cdr_put_u32(buf, pos, value):  # pragma: no cover - compiled
    buf[pos] = value & 0xFF
    buf[pos + 1] = (value >> 8) & 0xFF
    buf[pos + 2] = (value >> 16) & 0xFF
    buf[pos + 3] = (value >> 24) & 0xFF


@_jit
def skin_part_cdr_bytes(sec, nanosec, frame_id, body_part, cell_ids, sequence, accel_count, force_count,
                        temperature_c, tare, bad_frames, accel, a_off, a_scale, force, f_off, f_scale, proximity,
                        p_scale):  # pragma: no cover - compiled
    """A ``SkinPartFrames``' CDR bytes, as rclpy serialises the message the skin driver builds of the same arrays.

    The layout :func:`skin_part_cdr` reads (little-endian plain CDR, header ``00 01 00 00``; padding zero).
    ``frame_id`` and ``body_part`` are UTF-8 bytes without NUL (uint8); ``cell_ids``, ``sequence``,
    ``accel_count``, ``force_count`` and ``bad_frames`` (int64) are written as uint32 (their low 32 bits, as
    numpy casts them), ``tare`` (n, 3) run-major, ``accel`` (3, n_a) int16 as its three axes, ``force``
    (3, n_f) uint16 sample-major (``force[k * 3 + sensor]``).  Returns the bytes as a uint8 array whose
    payload starts 8 bytes aligned in memory.
    """
    n = cell_ids.shape[0]
    n_a = accel.shape[1]
    n_f = force.shape[1]
    seqs = (frame_id.shape[0] + 1, body_part.shape[0] + 1, n, n, n, n, n, 3 * n, n, n_a, n_a, n_a, n_a, -1, 3 * n_f,
            n_f, -1, proximity.shape[0], -1)
    n_plan = len(SKIN_PART_CDR_PLAN)
    ats = np.empty(n_plan, dtype=np.int64)  # where each field's length (a float64: the field) goes
    firsts = np.empty(n_plan, dtype=np.int64)  # and its first element
    pos = 12
    for i in range(n_plan):
        size = SKIN_PART_CDR_PLAN[i]
        if size < 0:
            ats[i] = _cdr_align(pos, 8)
            pos = ats[i] + 8
        else:
            ats[i], firsts[i], pos = _cdr_seq_at(pos, seqs[i], size)
    mem = np.zeros(pos // 8 + 2, dtype=np.float64).view(np.uint8)  # zeros: the padding bytes
    buf = mem[4:4 + pos]
    buf[1] = 1
    _cdr_put_u32(buf, 4, sec & 0xFFFFFFFF)
    _cdr_put_u32(buf, 8, nanosec)
    for i in range(n_plan):
        size = SKIN_PART_CDR_PLAN[i]
        at = ats[i]
        if size < 0:
            buf[at:at + 8].view(np.float64)[0] = a_scale if i == 13 else (f_scale if i == 16 else p_scale)
            continue
        first = firsts[i]
        end = first + seqs[i] * size
        _cdr_put_u32(buf, at, seqs[i])
        if i == 0 or i == 1:
            text = frame_id if i == 0 else body_part
            for k in range(text.shape[0]):
                buf[first + k] = text[k]
        elif i == 2 or i == 3 or i == 4 or i == 5 or i == 8:
            src = cell_ids if i == 2 else (sequence if i == 3 else (accel_count if i == 4 else
                                                                     (force_count if i == 5 else bad_frames)))
            out32 = buf[first:end].view(np.uint32)
            for k in range(n):
                out32[k] = np.uint32(src[k] & 0xFFFFFFFF)
        elif i == 6:
            buf[first:end].view(np.float64)[:] = temperature_c
        elif i == 7:
            out64 = buf[first:end].view(np.float64)
            for r in range(n):
                for c in range(3):
                    out64[3 * r + c] = tare[r, c]
        elif i == 9 or i == 10 or i == 11:
            buf[first:end].view(np.int16)[:] = accel[i - 9]
        elif i == 12:
            buf[first:end].view(np.int64)[:] = a_off
        elif i == 14:
            out16 = buf[first:end].view(np.uint16)
            for k in range(n_f):
                for c in range(3):
                    out16[3 * k + c] = force[c, k]
        elif i == 15:
            buf[first:end].view(np.int64)[:] = f_off
        else:
            buf[first:end].view(np.uint16)[:] = proximity
    return buf


@_jit
def check_runs(ids, seq, bad, served_ids, served_part, part_code, have, high, mine, out):  # pragma: no cover
    """Each run of a body part's message against the served cells and its cell's batch numbers, in run order.

    The compiled form of :meth:`..streams.skin_parts.RunChecker.check`: ``mine[i]`` says whether run ``i``
    is of a served cell of body part ``part_code``; for those, in order, the batch number ``seq[i]`` after
    the cell's newest (``high``, unwrapped; ``have``: one was seen) counts the batches between as lost, a
    number at or before it a restart.  ``out`` receives the unknown runs, the first unknown id, the runs of
    another body part's cells, the first such id, the lost batches, the restarts and the bad frames of the
    cell's runs; the sequence state is updated only when some run is the body part's.
    """
    n = ids.shape[0]
    m = served_ids.shape[0]
    n_unknown = 0
    n_other = 0
    first_unknown = -1
    first_other = -1
    any_mine = False
    for i in range(n):
        cid = ids[i]
        pos = min(_left_of(served_ids, 0, m, cid), m - 1)
        if m == 0 or served_ids[pos] != cid:
            mine[i] = False
            if n_unknown == 0:
                first_unknown = cid
            n_unknown += 1
        elif served_part[pos] != part_code:
            mine[i] = False
            if n_other == 0:
                first_other = cid
            n_other += 1
        else:
            mine[i] = True
            any_mine = True
    lost = 0
    restarts = 0
    bad_sum = 0
    if any_mine:
        for i in range(n):
            if not mine[i]:
                continue
            lo = _left_of(served_ids, 0, m, ids[i])  # a run of the body part's: its cell is there
            q = np.int64(seq[i])
            if have[lo]:
                d = (q - (high[lo] + 1)) % 4294967296
                if d >= 2147483648:
                    restarts += 1
                    high[lo] = q
                else:
                    lost += d
                    high[lo] = high[lo] + 1 + d
            else:
                high[lo] = q
            have[lo] = True
            bad_sum += np.int64(bad[i])
    out[0] = n_unknown
    out[1] = first_unknown
    out[2] = n_other
    out[3] = first_other
    out[4] = lost
    out[5] = restarts
    out[6] = bad_sum


# ------------------------------------------------------------------ a body part's message, reduced (contact)
@_jit
def skin_run_sums(f_count, force, tare, f_off, stamp_ns, a_count, accel, a_scale, invalid_count, invalid_accel,
                  d_sum, n_ok, s1, s2, n_a, newest, oldest):  # pragma: no cover - compiled
    """Each run's sums for :func:`..core.contact.reduce_skin_runs`, in one pass over its samples.

    ``f_count``, ``a_count`` (int64, one per run), ``force`` (uint16, (k, 3)), ``tare`` (float64, (runs,
    3)), ``f_off`` (int64 offsets from ``stamp_ns``) and ``accel`` (int16, (3, n)) are a message's arrays.
    Into ``d_sum`` (3, runs) goes each sensor's sum of ``count - tare`` over the run's samples with no
    sensor at ``invalid_count`` (another sample adds 0.0, as numpy's masked sum does), into ``n_ok`` those
    samples' number (float64), into ``newest`` and ``oldest`` their newest and oldest stamp (both -1
    without one, or when none is at or after 0); into ``s1``, ``s2`` (3, runs) each axis's sum and sum of
    squares of ``count * a_scale`` over the samples with no axis at ``invalid_accel`` (another adds
    ``0.0 * a_scale``), into ``n_a`` their number.  Every sum runs from 0.0 in sample order, as
    ``numpy.bincount`` adds its weights: the same operations in the same order, so the same bits.
    """
    runs = f_count.shape[0]
    k = 0
    for r in range(runs):
        c0 = tare[r, 0]
        c1 = tare[r, 1]
        c2 = tare[r, 2]
        d0 = 0.0
        d1 = 0.0
        d2 = 0.0
        ok_n = 0.0
        hi = np.int64(-1)
        lo = np.int64(9223372036854775807)
        for _ in range(f_count[r]):
            v0 = force[k, 0]
            v1 = force[k, 1]
            v2 = force[k, 2]
            if v0 != invalid_count and v1 != invalid_count and v2 != invalid_count:
                d0 += np.float64(v0) - c0
                d1 += np.float64(v1) - c1
                d2 += np.float64(v2) - c2
                ok_n += 1.0
                t = f_off[k] + stamp_ns
                if t > hi:
                    hi = t
                if t < lo:
                    lo = t
            else:
                d0 += 0.0
                d1 += 0.0
                d2 += 0.0
            k += 1
        d_sum[0, r] = d0
        d_sum[1, r] = d1
        d_sum[2, r] = d2
        n_ok[r] = ok_n
        newest[r] = hi
        oldest[r] = lo if hi >= 0 else -1
    i = 0
    for r in range(runs):
        x1 = 0.0
        y1 = 0.0
        z1 = 0.0
        x2 = 0.0
        y2 = 0.0
        z2 = 0.0
        m = 0.0
        for _ in range(a_count[r]):
            ax = accel[0, i]
            ay = accel[1, i]
            az = accel[2, i]
            if ax != invalid_accel and ay != invalid_accel and az != invalid_accel:
                x = np.float64(ax) * a_scale
                y = np.float64(ay) * a_scale
                z = np.float64(az) * a_scale
                m += 1.0
            else:
                x = 0.0 * a_scale
                y = 0.0 * a_scale
                z = 0.0 * a_scale
            x1 += x
            y1 += y
            z1 += z
            x2 += x * x
            y2 += y * y
            z2 += z * z
            i += 1
        s1[0, r] = x1
        s1[1, r] = y1
        s1[2, r] = z1
        s2[0, r] = x2
        s2[1, r] = y2
        s2[2, r] = z2
        n_a[r] = m


# ------------------------------------------------------------------ windowing intake
@_jit
def runs_in_order(t, counts, rows, n_rows, has_a, last_a, has_b, last_b):  # pragma: no cover - compiled
    """Whether a message's runs may be written as they are (:func:`.windowing._in_order`, one pass).

    Run ``i`` holds ``counts[i]`` samples of ``t`` (runs concatenated in
    order) for row ``rows[i]`` (every row ``0 <= r < n_rows``).  True when no
    row takes two runs, every run's stamps increase strictly, and every
    non-empty run starts after its row's newest stamp in both buffers
    (``has_*``, ``last_*``; pass one buffer twice to check one).
    """
    seen = np.zeros(n_rows, dtype=np.bool_)
    pos = 0
    for i in range(counts.shape[0]):
        r = rows[i]
        if r < 0 or r >= n_rows or seen[r]:
            return False
        seen[r] = True
        n = counts[i]
        if n < 0 or pos + n > t.shape[0]:
            return False
        if n > 0:
            first = t[pos]
            if (has_a[r] and first <= last_a[r]) or (has_b[r] and first <= last_b[r]):
                return False
            for k in range(pos + 1, pos + n):
                if t[k] <= t[k - 1]:
                    return False
        pos += n
    return True


@_jit
def _room(hi, cap, rows, counts):  # pragma: no cover - compiled
    """Whether every run ``i`` (``counts[i]`` samples) fits after row ``rows[i]``'s end in a capacity ``cap``."""
    for i in range(counts.shape[0]):
        if hi[rows[i]] + counts[i] > cap:
            return False
    return True


@_jit
def append_runs(t_buf, v_buf, ok_buf, hi, last, has, rows, counts, t, values, valid, use_valid
                ):  # pragma: no cover - compiled
    """Write run ``i`` (``counts[i]`` samples of ``t``, ``values``, ``valid``) after row ``rows[i]``'s end.

    The compiled form of :meth:`.windowing._RowBuffer.append_runs` for rows
    taking one run each, checked by :func:`runs_in_order`: the same copies,
    sample by sample instead of through a flat index per sample.  Returns
    False, having written nothing, when a run does not fit in its row's
    remaining capacity (the caller makes room and writes it itself).
    """
    if not _room(hi, t_buf.shape[1], rows, counts):
        return False
    n_ch = v_buf.shape[0]
    pos = 0
    for i in range(counts.shape[0]):
        r = rows[i]
        n = counts[i]
        h = hi[r]
        for k in range(n):
            t_buf[r, h + k] = t[pos + k]
        if use_valid:
            for k in range(n):
                ok_buf[r, h + k] = valid[pos + k]
        else:
            for k in range(n):
                ok_buf[r, h + k] = True
        for c in range(n_ch):
            for k in range(n):
                v_buf[c, r, h + k] = values[c, pos + k]
        if n > 0:
            hi[r] = h + n
            last[r] = t[pos + n - 1]
            has[r] = True
        pos += n
    return True


@_jit
def _left_of(t, a, b, value):  # pragma: no cover - compiled
    """The first position in ``t[a:b]`` (sorted) whose value is not below ``value`` (``b`` if none): a
    ``searchsorted`` (side left) of that slice, as a position in ``t``."""
    while a < b:
        m = (a + b) >> 1
        if t[m] < value:
            a = m + 1
        else:
            b = m
    return a


@_jit
def _add_counts(added, rows, counts):  # pragma: no cover - compiled
    """Count run ``i``'s ``counts[i]`` samples in ``added[rows[i]]`` (a row buffer's appended samples)."""
    for i in range(counts.shape[0]):
        added[rows[i]] += counts[i]


@_jit
def add_part_runs(rows, vc, dc, t_v, vib, vib_valid, use_vib_valid, t_d, dfm, dfm_valid, use_dfm_valid, extra,
                  use_extra, force_n, vt, vv, vok, vhi, vlast, vhas, vadded, dt, dv, dok, dhi, dlast, dhas, dadded,
                  et, ev, eok, ehi, elast, ehas, eadded, ft, fv, fok, flo, fhi, flast, fhas, fadded, explore,
                  release_n, hot_until, hot, smooth_ns, last_force):  # pragma: no cover - compiled
    """A body part's message into its four buffers in one call: 0 written, 1 not in order, 2 out of room.

    The compiled form of :meth:`.windowing.Windower.add_part`'s array path
    for a body part that has buffers: the checks of ``_fast_ok`` (the runs'
    lengths agree with the arrays, every run has vibration samples, each
    row takes at most one run, stamps increase from where the row's buffers
    end: :func:`runs_in_order`), then :func:`append_runs` into the
    vibration (``v*``), deformation (``d*``), extra (``e*``, when
    ``use_extra``; no validity) and force (``f*``; no validity) buffers,
    each buffer's ``added`` counts, and in exploration mode
    :func:`explore_runs`.  Returns 1 (nothing written) where the message
    must go run by run, 2 (nothing written) where a row lacks room (the
    caller makes room with numpy).  One call instead of five and their
    Python checks: the Python around them took three quarters of the intake.
    """
    n = rows.shape[0]
    if vc.shape[0] != n or dc.shape[0] != n or n == 0:
        return 1
    n_a = 0
    n_d = 0
    for i in range(n):
        if vc[i] <= 0 or dc[i] < 0:
            return 1
        n_a += vc[i]
        n_d += dc[i]
    if vib.shape[0] != vv.shape[0] or vib.shape[1] != n_a or t_v.shape[0] != n_a:
        return 1
    if dfm.shape[0] != dv.shape[0] or dfm.shape[1] != n_d or t_d.shape[0] != n_d or force_n.shape[0] != n_d:
        return 1
    if (use_vib_valid and vib_valid.shape[0] != n_a) or (use_dfm_valid and dfm_valid.shape[0] != n_d):
        return 1
    if use_extra and (extra.shape[0] != ev.shape[0] or extra.shape[1] != n_d):
        return 1
    n_rows = vt.shape[0]
    if not (runs_in_order(t_v, vc, rows, n_rows, vhas, vlast, vhas, vlast)
            and runs_in_order(t_d, dc, rows, n_rows, dhas, dlast, fhas, flast)):
        return 1
    if not (_room(vhi, vt.shape[1], rows, vc) and _room(dhi, dt.shape[1], rows, dc)
            and _room(fhi, ft.shape[1], rows, dc) and (not use_extra or _room(ehi, et.shape[1], rows, dc))):
        return 2
    append_runs(vt, vv, vok, vhi, vlast, vhas, rows, vc, t_v, vib, vib_valid, use_vib_valid)
    _add_counts(vadded, rows, vc)
    if n_d:
        append_runs(dt, dv, dok, dhi, dlast, dhas, rows, dc, t_d, dfm, dfm_valid, use_dfm_valid)
        _add_counts(dadded, rows, dc)
        if use_extra:
            append_runs(et, ev, eok, ehi, elast, ehas, rows, dc, t_d, extra, dfm_valid, False)
            _add_counts(eadded, rows, dc)
        append_runs(ft, fv, fok, fhi, flast, fhas, rows, dc, t_d, force_n.reshape((1, n_d)), dfm_valid, False)
        _add_counts(fadded, rows, dc)
    if explore:
        explore_runs(rows, dc, t_d, force_n, release_n, hot_until, hot, ft, fv, flo, fhi, smooth_ns, last_force)
    return 0


@_jit
def trim_rows(t_buf, lo, hi, has, t_ns):  # pragma: no cover - compiled
    """Drop every row's samples older than ``t_ns``; how many rows lost any.

    The compiled form of :meth:`.windowing._RowBuffer.trim_before`: a row
    (samples between ``lo[r]`` and ``hi[r]``, in time order) whose oldest
    sample is older starts at its first sample not older (``searchsorted``
    left), and a row left with none loses ``has[r]``.  The window node trims
    its 28 buffers of NAO cells (7 body parts) every 100 ms of data: a search
    per row in Python took 2 % of a core.
    """
    moved = 0
    for r in range(lo.shape[0]):
        a = lo[r]
        b = hi[r]
        if b > a and t_buf[r, a] < t_ns:
            i = _left_of(t_buf[r], a, b, t_ns)
            lo[r] = i
            if i == b:
                has[r] = False
            moved += 1
    return moved


@_jit
def cut_rows(t_buf, ok_buf, lo, hi, start, end, scan, first, stop, n_bad, widest):  # pragma: no cover - compiled
    """Each row's samples with ``start <= t < end``: where they are, how many are invalid, the widest step.

    The compiled form of the cut that :meth:`.windowing.Windower._make_window`
    makes of every row of a body part's buffer (row ``r`` holds its samples
    between ``lo[r]`` and ``hi[r]``, in time order): ``first[r]``,
    ``stop[r]`` are the positions of the window's samples (``searchsorted``
    left of ``start`` and of ``end``), ``n_bad[r]`` how many of them are not
    valid, and ``widest[r]`` the longest step between the window's valid
    samples with ``start`` and ``end`` as the outer edges (``end - start``
    when none is valid).  ``scan`` says what is looked at beyond the
    positions: 2 both, 1 the invalid samples only (``widest`` is 0), 0
    nothing (``n_bad`` and ``widest`` are 0): a row's samples are read only
    where the caller uses what they give.
    """
    for r in range(lo.shape[0]):
        i = _left_of(t_buf[r], lo[r], hi[r], start)
        a = _left_of(t_buf[r], i, hi[r], end)
        first[r] = i
        stop[r] = a
        n_bad[r] = 0
        widest[r] = 0
        if scan == 1:
            bad = 0
            for k in range(i, a):
                bad += 1 - np.int64(ok_buf[r, k])
            n_bad[r] = bad
            continue
        if scan != 2:
            continue
        bad = 0
        prev = start
        step = 0
        for k in range(i, a):
            if ok_buf[r, k]:
                if t_buf[r, k] - prev > step:
                    step = t_buf[r, k] - prev
                prev = t_buf[r, k]
            else:
                bad += 1
        if end - prev > step:
            step = end - prev
        n_bad[r] = bad
        widest[r] = step


@_jit
def explore_runs(rows, counts, t, f, release_n, hot_until, hot, f_t, f_v, f_lo, f_hi, smooth_ns, last_force
                 ):  # pragma: no cover - compiled
    """Exploration state of a message's cells after its force runs were buffered (:meth:`.windowing.Windower._add_runs`).

    Per non-empty run ``i`` (``counts[i]`` samples of stamps ``t`` and
    forces ``f``, runs concatenated in order; each row at most one run): a
    run whose largest force (NaN ignored, as ``numpy.fmax``) reaches
    ``release_n`` marks its row hot until its last stamp; the row's latest
    smoothed force becomes the mean of its buffered finite forces ``f_v[0, r]``
    stamped within ``smooth_ns`` of its newest (kept when none is finite),
    summed in sample order.
    """
    pos = 0
    for i in range(counts.shape[0]):
        n = counts[i]
        if n <= 0:
            continue
        r = rows[i]
        peak = np.nan
        for k in range(pos, pos + n):
            x = f[k]
            if x == x and (peak != peak or x > peak):  # fmax: a NaN never wins over a number
                peak = x
        if peak >= release_n:
            hot_until[r] = t[pos + n - 1]
            hot[r] = True
        pos += n
        lo = f_lo[r]
        hi = f_hi[r]
        if hi <= lo:
            continue
        start = f_t[r, hi - 1] - smooth_ns
        j = hi - 1
        while j > lo and f_t[r, j - 1] >= start:
            j -= 1
        total = 0.0
        m = 0
        for k in range(j, hi):
            x = f_v[0, r, k]
            if np.isfinite(x):
                total += x
                m += 1
        if m > 0:
            last_force[r] = total / m


#: Frame verdicts of :func:`decode_can_rows`, in the order the decoder checks them
#: (:meth:`~tactile_descriptors_ros.codecs.skin_can.SkinCanDecoder.decode`).
CAN_OK, CAN_REMOTE_OR_ERROR, CAN_FOREIGN, CAN_UNKNOWN_MODALITY, CAN_BAD_LENGTH, CAN_UNKNOWN_CELL, CAN_BAD_PAYLOAD = \
    0, 1, 2, 3, 4, 5, 6


@_jit
def decode_can_rows(flags, arb, dlc, data, ts, known, rejected_flags, extended_flag, tag, size_by_mod, period_by_mod,
                    status, values, seq, code, t, period, stamp):  # pragma: no cover - compiled
    """Skin-cell CAN frames (the fields of ``CAN_FRAME_DTYPE``) checked and unpacked in one pass.

    Each frame gets a verdict in ``status`` (``CAN_*``): a flag of
    ``rejected_flags`` (remote, error), then ``extended_flag`` and the
    arbitration id's tag, a modality with a payload size in ``size_by_mod``,
    the length ``1 + size_by_mod[modality]``, ``known[cell]``, then the
    payload's must-be-zero bits and reserved values, as
    :func:`~tactile_descriptors_ros.codecs.skin.unpack_values` checks them
    (modality numbers 1-4: accelerometer, force, proximity, temperature).
    The accepted frames go, in order, to the first ``k`` rows of ``values`` (accelerometer and force: 3 values;
    proximity and temperature: 1, then zeros), ``seq`` (the sequence byte),
    ``code`` (``cell << 4 | modality``), ``t`` (the bus time in ns rounded
    half to even, -1 without one), ``period`` (``period_by_mod[modality]``)
    and ``stamp`` (the bus time, ``int64`` minimum without one).  Returns
    ``k`` and whether any accepted frame has a bus time.
    """
    k = 0
    any_stamped = False
    no_stamp = np.iinfo(np.int64).min
    for i in range(arb.shape[0]):
        fl = flags[i]
        if fl & rejected_flags:
            status[i] = CAN_REMOTE_OR_ERROR
            continue
        a = np.int64(arb[i])
        if (fl & extended_flag) == 0 or ((a >> 20) & 0x1FF) != tag:
            status[i] = CAN_FOREIGN
            continue
        m = (a >> 16) & 0xF
        size = size_by_mod[m]
        if size == 0:
            status[i] = CAN_UNKNOWN_MODALITY
            continue
        if np.int64(dlc[i]) != 1 + size:
            status[i] = CAN_BAD_LENGTH
            continue
        cell = a & 0xFFFF
        if not known[cell]:
            status[i] = CAN_UNKNOWN_CELL
            continue
        w = np.int64(0)
        for b in range(size):
            w = (w << 8) | np.int64(data[i, 1 + b])
        v0 = np.int64(0)
        v1 = np.int64(0)
        v2 = np.int64(0)
        if m == 1:
            ok = (w >> 30) == 0
            v0 = (w >> 20) & 0x3FF
            v1 = (w >> 10) & 0x3FF
            v2 = w & 0x3FF
            if v0 & 0x200:
                v0 -= 1024
            if v1 & 0x200:
                v1 -= 1024
            if v2 & 0x200:
                v2 -= 1024
        elif m == 2:
            ok = (w & 0xF) == 0
            v0 = (w >> 28) & 0xFFF
            v1 = (w >> 16) & 0xFFF
            v2 = (w >> 4) & 0xFFF
        elif m == 3:
            ok = w != 0xFFFF
            v0 = w
        else:
            v0 = w - 0x10000 if w & 0x8000 else w
            ok = v0 != -32768
        if not ok:
            status[i] = CAN_BAD_PAYLOAD
            continue
        status[i] = CAN_OK
        values[k, 0] = v0
        values[k, 1] = v1
        values[k, 2] = v2
        seq[k] = np.int64(data[i, 0])
        code[k] = (cell << 4) | m
        period[k] = period_by_mod[m]
        s = ts[i]
        if s == 0.0:
            t[k] = -1
            stamp[k] = no_stamp
        else:
            any_stamped = True
            t[k] = np.int64(np.rint(s * 1e9))
            stamp[k] = t[k]
        k += 1
    return k, any_stamped


@_jit
def track_forward(slot, seq, t, period, modulus, live, low, high, t_high, deferred, events, unwrapped, gap_slot,
                  gap_from, gap_to):  # pragma: no cover - compiled
    """Sequence numbers in arrival order, each key's forward steps on its slot's state
    (:meth:`~tactile_descriptors_ros.codecs.sequence.SequenceTracker.track_many`).

    Number ``i`` (key slot ``slot[i]``, ``seq[i]`` already below ``modulus``,
    time ``t[i]`` [ns] and frame period ``period[i]``; ``t`` < 0 or ``period``
    <= 0: no time) is unwrapped against its key's newest number ``high``
    (:func:`~tactile_descriptors_ros.codecs.sequence.unwrap`, the elapsed
    periods since the newest as the expected advance).  A key's first number
    starts it (event 0, FIRST); a number past the newest is the next one
    (1, IN_ORDER) or follows a gap (2, GAP: ``gap_slot``, ``gap_from`` and
    ``gap_to`` get the slot and the skipped numbers ``gap_from..gap_to - 1``).
    Any other number (a duplicate, a late frame, a restart) needs the
    tracker's memory of holes: it and every later number of its key are left
    to the caller, event -1 (``deferred`` marks the slot).  Returns the
    number of gaps, the frames they lost and the numbers left to the caller.
    """
    n_gaps = 0
    lost = 0
    left = 0
    for i in range(slot.shape[0]):
        s = slot[i]
        if deferred[s]:
            events[i] = -1
            left += 1
            continue
        ti = t[i]
        if ti < 0:
            ti = -1
        if not live[s]:
            live[s] = True
            low[s] = seq[i]
            high[s] = seq[i]
            t_high[s] = ti
            events[i] = 0
            unwrapped[i] = seq[i]
            continue
        h = high[s]
        advance = 0.0
        th = t_high[s]
        if ti >= 0 and th >= 0 and period[i] > 0:
            advance = (ti - th) / period[i]
        d = (seq[i] - h) % modulus
        j = np.int64(np.ceil((advance - d) / modulus - 0.5))
        u = h + d + j * modulus
        if u <= h:
            deferred[s] = True
            events[i] = -1
            left += 1
            continue
        if u == h + 1:
            events[i] = 1
        else:
            events[i] = 2
            gap_slot[n_gaps] = s
            gap_from[n_gaps] = h + 1
            gap_to[n_gaps] = u
            n_gaps += 1
            lost += u - h - 1
        high[s] = u
        t_high[s] = ti
        unwrapped[i] = u
    return n_gaps, lost, left


@_jit
def _observe_key(k, dev_max, host_ns, offset, anchored, last_dev, high_since, high_min, last_excess, drift, jump_ns,
             confirm_ns):  # pragma: no cover - compiled
    """:meth:`~tactile_descriptors_ros.streams.clock.DeviceClock.observe` of one key on the clock's arrays: the
    lower envelope of host - device time, never above this observation; returns the key's offset and whether
    it was re-anchored."""
    obs = host_ns - dev_max
    resynced = 0
    new = not anchored[k]
    off = offset[k]
    last = last_dev[k]
    step = dev_max - last
    if step < 0:
        step = 0
    allowed = off + np.int64(step * drift)
    est = obs if obs < allowed else allowed
    back = False
    if jump_ns:
        back = (not new) and dev_max < last - jump_ns
        high = (not new) and (not back) and obs - est > jump_ns
        since = high_since[k]
        start = high and since < 0
        if start:
            since = host_ns
        elif not high:
            since = -1
        low = obs if start else (high_min[k] if high_min[k] < obs else obs)
        lasting = high and host_ns - since >= confirm_ns
        if back:
            est = obs
        elif lasting:
            est = low
        if back or lasting:
            resynced = 1
            since = -1
        high_since[k] = since
        high_min[k] = low
    if new:
        est = obs
        high_since[k] = -1
    offset[k] = est
    if new or back:
        last_dev[k] = dev_max
    elif dev_max > last:
        last_dev[k] = dev_max
    last_excess[k] = obs - est
    anchored[k] = True
    return est, resynced


@_jit
def skin_stamp_add(ks, useq, starts, ends, vals, given_t, period, clk_last, clk_have, st_t, st_seq, st_have, offset,
                   anchored, last_dev, high_since, high_min, last_excess, drift, jump_ns, confirm_ns, host_ns, lost,
                   lost_since, samples, last_mono, mono_now, temperature, first_t, has_first, last_a, has_a, last_f,
                   has_f, recent_t, recent_v, recent_pos, recent_n, out_t, out_c, out_v, counts):  # pragma: no cover
    """One read's samples of a skin stream, after the sequence tracker, in one pass
    (:meth:`~tactile_descriptors_ros.streams.skin.SkinStream._add_batch`, whose numpy code is the reference).

    The rows are grouped by key (``cell * 4 + modality - 1``; group ``g`` is rows ``starts[g]..ends[g] - 1``,
    arrival order within it); ``useq`` their unwrapped sequence numbers, ``vals`` their values, ``given_t``
    their ``device`` stamps (empty: ``clock`` stamps, made here). Per group, in the reference's order: frames
    lost (jumps past the highest number seen); for ``clock`` stamps the key's device clock observed
    (:meth:`~tactile_descriptors_ros.streams.clock.DeviceClock.observe` on its arrays, host time ``host_ns``),
    its samples stamped and those stepping back in time dropped; the cell's counters, last
    temperature, first and newest stamps and remembered force samples (``RECENT_FORCE`` = ``recent_t``'s
    width) updated.  The kept accelerometer, force and proximity samples go to ``out_t[m]``, ``out_c[m]``
    (cell index), ``out_v[m]`` for ``m`` = 0, 1, 2; ``counts`` gets how many of each, the samples dropped
    and the keys re-anchored.
    """
    n_rec = recent_t.shape[1]
    n_cells = first_t.shape[0]
    big = np.iinfo(np.int64).max
    first_read = np.full(n_cells, big, np.int64)
    n_out = np.zeros(3, np.int64)
    back_total = 0
    resyncs = 0
    clock = given_t.shape[0] == 0
    for g in range(starts.shape[0]):
        s = starts[g]
        e = ends[g]
        k = ks[s]
        cell = k // 4
        mod = k % 4  # 0 accelerometer, 1 force, 2 proximity, 3 temperature
        per = period[mod]
        # frames lost: jumps beyond the highest number seen so far
        h = clk_last[k] if clk_have[k] else useq[s] - 1
        lost_sum = 0
        q_max = useq[s]
        for i in range(s, e):
            if i > s and useq[i - 1] > h:
                h = useq[i - 1]
            d = useq[i] - h - 1
            if d > 0:
                lost_sum += d
            if useq[i] > q_max:
                q_max = useq[i]
        clk_have[k] = True
        clk_last[k] = h if h > useq[e - 1] else useq[e - 1]
        lost[cell] += lost_sum
        lost_since[cell] += lost_sum
        # the cell's counters and last temperature (every sample of the read)
        samples[cell] += e - s
        last_mono[cell] = mono_now
        if mod == 3:
            temperature[cell] = vals[e - 1, 0] * 0.01
        if clock:
            dev_max = np.int64(np.rint(q_max * per))  # the newest device time: rint(q * period) grows with q
            est, resynced = _observe_key(k, dev_max, host_ns, offset, anchored, last_dev, high_since, high_min,
                                         last_excess, drift, jump_ns, confirm_ns)
            resyncs += resynced
        else:
            est = 0
        # stamps; a sample newer in sequence than the key's last stamped one but not later in time is dropped
        had = st_have[k]
        t_prev = st_t[k]
        q_prev = st_seq[k]
        newest_t = np.iinfo(np.int64).min
        newest_q = np.iinfo(np.int64).min
        rank = 0
        for i in range(s, e):
            if clock:
                t = np.int64(np.rint(useq[i] * per)) + est
                if had and useq[i] > q_prev and t <= t_prev:
                    back_total += 1
                    continue
            else:
                t = given_t[i]
            if t > newest_t:
                newest_t = t
            if useq[i] > newest_q:
                newest_q = useq[i]
            if t < first_read[cell]:
                first_read[cell] = t
            if mod == 1:  # the last RECENT_FORCE force samples of the cell, a ring
                slot = (recent_pos[cell] + rank) % n_rec
                recent_t[cell, slot] = t
                for j in range(3):
                    recent_v[cell, slot, j] = vals[i, j]
                rank += 1
            if mod < 3:
                m = n_out[mod]
                out_t[mod, m] = t
                out_c[mod, m] = cell
                for j in range(3):
                    out_v[mod, m, j] = vals[i, j]
                n_out[mod] = m + 1
        if newest_q > np.iinfo(np.int64).min:
            if clock:
                st_t[k] = newest_t if not had or newest_t > t_prev else t_prev
                st_seq[k] = newest_q if not had or newest_q > q_prev else q_prev
                st_have[k] = True
            if mod == 0:
                last_a[cell] = newest_t if not has_a[cell] or newest_t > last_a[cell] else last_a[cell]
                has_a[cell] = True
            elif mod == 1:
                last_f[cell] = newest_t if not has_f[cell] or newest_t > last_f[cell] else last_f[cell]
                has_f[cell] = True
        if mod == 1:
            recent_pos[cell] = (recent_pos[cell] + rank) % n_rec
            recent_n[cell] = min(recent_n[cell] + rank, n_rec)
    for c in range(n_cells):
        if not has_first[c] and first_read[c] < big:
            first_t[c] = first_read[c]
            has_first[c] = True
    counts[0] = n_out[0]
    counts[1] = n_out[1]
    counts[2] = n_out[2]
    counts[3] = back_total
    counts[4] = resyncs
