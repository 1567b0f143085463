"""The descriptor's hot path: per-cell quantities (paper eq. 1-5) by the compiled kernel.

:func:`cell_quantities` is what every caller runs (the window node through
:func:`~.aggregation.describe_window`, ``tactile evaluate``, ``tactile
report``, ``tactile bench``).  It hands integer sensor data (ADC counts, as
every driver and dataset delivers them) to a compiled backend, which
computes every quantity from exact integer sums in one pass per cell
(:mod:`.numba_kernel`); whatever a backend cannot compute exactly (float
data, integers too large for exact sums, windows of fewer than 3 samples or
pairs, unsorted stamps) is computed by the reference,
:func:`.descriptors.cell_quantities`, the paper's maths as it is written.
Both give the same values to rounding and the same quality flags; property
tests keep them equal (``test/core/test_fast_paths.py``).

Backends are registered by name in :data:`BACKENDS` (module path, imported
on first use, as python-can registers its interfaces).  The first one that
imports serves; ``"reference"`` (no compiled code) serves when none does,
when ``TACTILE_NO_NUMBA=1`` is set, or when :func:`set_backend` chooses it.
Compiled code is cached on disk; ``make setup`` fills the cache
(:func:`main`, :func:`warm_up`), so nodes start without compiling.

Scratch arrays reused between calls live in one per-thread pool
(:func:`scratch`, :func:`release_buffers`): on these machines a fresh
multi-megabyte array costs more in page faults than the arithmetic on it.
"""

from __future__ import annotations

import importlib
import math
import os
import threading
import time
from types import ModuleType

import numpy as np

from ..errors import SignalError
from . import descriptors
from .descriptors import Quality

__all__ = [
    "BACKENDS",
    "REFERENCE",
    "backend",
    "kernel_module",
    "set_backend",
    "cell_quantities",
    "cell_quantities_bounded",
    "cell_bounds",
    "exact_integer_ok",
    "scratch",
    "release_buffers",
    "warm_up",
    "warm_up_codecs",
    "main",
]

#: Compiled backends by name: the module that implements them, imported on
#: first use.  A backend module provides ``quantities``, ``cell_bounds``,
#: ``central_moments``, ``power_spectrum``, ``band_moments``, ``rocket_ppv``, the windowing intake's
#: ``runs_in_order``, ``append_runs`` and ``explore_runs``, the message conversion ``skin_part_arrays`` and
#: check ``check_runs``,
#: the CAN decoder's ``decode_can_rows`` (and its verdicts ``CAN_*``), the sequence tracker's
#: ``track_forward``, the status ``OK`` and ``CACHE_DIR`` (:mod:`.numba_kernel` documents them).
#: The first name that imports serves.
BACKENDS: dict[str, str] = {"numba": f"{__package__}.numba_kernel"}

#: The name of the reference (:func:`.descriptors.cell_quantities`, no compiled code).
REFERENCE: str = "reference"

_F64_EXACT = float(2**53)
_I64_SAFE = float(2**62)
_U_FLAT = np.uint32(Quality.FLAT)


# ------------------------------------------------------------- buffer pool
class _Pool(threading.local):
    """Scratch arrays reused between calls, one set per thread."""

    def __init__(self) -> None:
        self.arrays: dict[tuple[str, str], np.ndarray] = {}


_POOL = _Pool()


def scratch(slot: str, shape: tuple[int, ...], dtype) -> np.ndarray:
    """A reused array of ``shape`` and ``dtype`` for ``slot`` (valid until the next call for that slot).

    Parameters
    ----------
    slot : str
        Name of the use; one array per slot and dtype per thread.
    shape : tuple of int
    dtype : numpy dtype

    Returns
    -------
    numpy.ndarray
        Uninitialised contents.
    """
    size = math.prod(shape)
    key = (slot, np.dtype(dtype).str)
    buf = _POOL.arrays.get(key)
    if buf is None or buf.size < size:
        buf = _POOL.arrays[key] = np.empty(max(size, 1), dtype=dtype)
    return buf[:size].reshape(shape)


def release_buffers() -> int:
    """Free this thread's scratch arrays; return the bytes released."""
    total = sum(b.nbytes for b in _POOL.arrays.values())
    _POOL.arrays.clear()
    return total


# ---------------------------------------------------------------- backends
_LOCK = threading.Lock()
_STATE: dict = {"resolved": False, "name": REFERENCE, "module": None, "forced": None, "load_s": None,
                "error": None}


def _load(name: str) -> ModuleType:
    return importlib.import_module(BACKENDS[name])


def kernel_module() -> ModuleType | None:
    """The compiled backend's module (loaded on first call), or None when the reference serves.

    A backend module provides what :data:`BACKENDS` lists; the feature
    groups (:mod:`.features`) call its ``central_moments`` and
    ``power_spectrum`` directly.
    """
    if _STATE["resolved"]:
        return _STATE["module"]
    with _LOCK:
        if not _STATE["resolved"]:
            name, module = REFERENCE, None
            forced = _STATE["forced"]
            disabled = os.environ.get("TACTILE_NO_NUMBA", "") not in ("", "0")
            if forced != REFERENCE and not (forced is None and disabled):
                t0 = time.perf_counter()
                for candidate in ([forced] if forced else list(BACKENDS)):
                    try:
                        module, name = _load(candidate), candidate
                        break
                    except ImportError as exc:  # numba missing or broken: the reference serves
                        _STATE["error"] = f"{type(exc).__name__}: {exc}"
                _STATE["load_s"] = time.perf_counter() - t0
            _STATE.update(name=name, module=module, resolved=True)
    return _STATE["module"]


def backend() -> str:
    """The name of the backend in use: a key of :data:`BACKENDS`, or :data:`REFERENCE`."""
    kernel_module()
    return _STATE["name"]


def set_backend(name: str | None) -> str:
    """Choose a backend by name (``None``: the default); return the previous one.

    Raises
    ------
    ImportError
        For a compiled backend that cannot be imported.
    SignalError
        For a name that is neither in :data:`BACKENDS` nor :data:`REFERENCE`.
    """
    if name is not None and name != REFERENCE and name not in BACKENDS:
        raise SignalError(f"backend must be one of {sorted([*BACKENDS, REFERENCE])} or None, got {name!r}")
    previous = backend()
    with _LOCK:
        _STATE.update(forced=name, resolved=False, error=None)
        if name is not None and name != REFERENCE:
            _STATE.update(name=name, module=_load(name), resolved=True)
    return previous


# ------------------------------------------------------------------ kernel
def exact_integer_ok(n: int, *peaks: float) -> bool:
    """Whether integer data of ``n`` samples and these peaks have exact moments.

    Sums of products of two signals (or of a signal's second difference, up
    to 4 peaks) must stay below 2**53 to be exact in float64, and ``n`` times
    them below 2**62 to combine exactly in int64.

    Examples
    --------
    >>> exact_integer_ok(2000, 4095)       # 2 s of 12-bit force at 1 kHz
    True
    >>> exact_integer_ok(2000, 2.0**40)
    False
    """
    p = 4.0 * max(max(peaks, default=0.0), 1.0)
    return n * p * p < _F64_EXACT and float(n) * n * p * p < _I64_SAFE


def loaded_layout(*arrays: np.ndarray) -> bool:
    """Whether every array has the layout of the compiled variants :func:`warm_up` loads: C-contiguous and
    writeable.

    numba compiles a function once per argument layout and read-only flag, so a strided view or a
    read-only buffer (a bag reader's) would compile another variant (seconds) while a node runs; callers
    take their numpy path for those instead.
    """
    for a in arrays:
        flags = a.flags
        if not (flags.c_contiguous and flags.writeable):
            return False
    return True


def _compiled_int(x: np.ndarray) -> np.ndarray | None:
    """``x`` as C-contiguous int32 or int64 for the compiled kernel (None for non-integers and uint64)."""
    if x.dtype == np.int32 or x.dtype == np.int64:
        return np.ascontiguousarray(x)
    if x.dtype == bool or x.dtype.kind in "iu" and x.dtype.itemsize < 4:
        return x.astype(np.int32)
    if x.dtype == np.uint32:
        return x.astype(np.int64)
    return None


def _check_rate(fs_hz: float) -> float:
    fs = float(fs_hz)
    if not math.isfinite(fs) or fs <= 0:
        raise SignalError(f"fs_hz must be a positive finite rate, got {fs_hz!r}")
    return fs


def cell_quantities(s: np.ndarray, t_s_ns: np.ndarray, v: np.ndarray, t_v_ns: np.ndarray,
                    rate_s_hz: float, rate_v_hz: float) -> tuple[np.ndarray, ...]:
    """Every per-cell quantity of eq. 1-5 for a batch of cells, fast and exact.

    Same parameters and returns as :func:`.descriptors.cell_quantities`
    (the fields of :class:`~.aggregation.CellFeatures` in order), which
    computes what the compiled backend hands back.

    Parameters
    ----------
    s : array_like, shape (n_cells, n_s, n_fast)
    t_s_ns : array_like of int64, shape (n_fast,) or (n_cells, n_fast)
    v : array_like, shape (n_cells, n_v, n_slow)
    t_v_ns : array_like of int64, shape (n_slow,) or (n_cells, n_slow)
    rate_s_hz, rate_v_hz : float

    Returns
    -------
    tuple of numpy.ndarray
    """
    s = np.asarray(s)
    v = np.asarray(v)
    ts = np.asarray(t_s_ns, dtype=np.int64)
    tv = np.asarray(t_v_ns, dtype=np.int64)
    descriptors.check_cell_batch(s, ts, v, tv)
    fs_s, fs_v = _check_rate(rate_s_hz), _check_rate(rate_v_hz)
    res = _compiled(s, ts, v, tv, fs_s, fs_v)
    if res is not None:
        return res[0]
    return descriptors.cell_quantities(s, ts, v, tv, fs_s, fs_v)


def _compiled(s: np.ndarray, ts: np.ndarray, v: np.ndarray, tv: np.ndarray, fs_s: float, fs_v: float
              ) -> tuple[tuple[np.ndarray, ...], np.ndarray] | None:
    """The compiled backend's quantities and per-cell bounds, or None when it cannot compute the batch exactly."""
    kernel = kernel_module()
    if kernel is None or not (min(s.shape) and min(v.shape) and s.shape[2] >= 3 and v.shape[2] >= 3):
        return None
    s_c, v_c = _compiled_int(s), _compiled_int(v)
    if s_c is None or v_c is None:
        return None
    bounds = np.empty((s.shape[0], 4), dtype=np.int64)
    status, *out = kernel.quantities(s_c, np.ascontiguousarray(ts[None, :] if ts.ndim == 1 else ts), v_c,
                                     np.ascontiguousarray(tv[None, :] if tv.ndim == 1 else tv), fs_s, fs_v, _U_FLAT,
                                     max(4 * s.shape[2], 1 << 16), bounds)
    return (tuple(out), bounds) if status == kernel.OK else None


def cell_quantities_bounded(s: np.ndarray, t_s_ns: np.ndarray, v: np.ndarray, t_v_ns: np.ndarray,
                            rate_s_hz: float, rate_v_hz: float) -> tuple[tuple[np.ndarray, ...], np.ndarray] | None:
    """:func:`cell_quantities` and each cell's value bounds, when the compiled backend computes the batch exactly.

    Parameters
    ----------
    s, t_s_ns, v, t_v_ns, rate_s_hz, rate_v_hz
        As :func:`cell_quantities`.

    Returns
    -------
    (tuple of numpy.ndarray, numpy.ndarray) or None
        The quantities (as :func:`cell_quantities` returns them) and an
        ``(n_cells, 4)`` int64 array of each cell's smallest and largest S
        value and smallest and largest V value; None when there is no
        compiled backend or it cannot compute this batch exactly (integer
        data within :func:`exact_integer_ok`, 3 or more samples and pairs,
        sorted stamps): call :func:`cell_quantities` then.
    """
    s = np.asarray(s)
    v = np.asarray(v)
    ts = np.asarray(t_s_ns, dtype=np.int64)
    tv = np.asarray(t_v_ns, dtype=np.int64)
    descriptors.check_cell_batch(s, ts, v, tv)
    return _compiled(s, ts, v, tv, _check_rate(rate_s_hz), _check_rate(rate_v_hz))


def cell_bounds(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Smallest and largest value of each cell of integer data (n_cells, channels, samples)."""
    kernel = kernel_module()
    xc = _compiled_int(x) if kernel is not None and x.ndim == 3 and x.shape[1] * x.shape[2] else None
    if xc is None:
        return x.min(axis=(1, 2)), x.max(axis=(1, 2))
    lo = np.empty(x.shape[0], dtype=np.int64)
    hi = np.empty(x.shape[0], dtype=np.int64)
    kernel.cell_bounds(xc.reshape(x.shape[0], -1), lo, hi)
    return lo, hi


# ------------------------------------------------------------------ set-up
def warm_up() -> dict:
    """Load (or compile) the compiled backend's code now; return what it took.

    The first call of each compiled function in a process loads it from the
    on-disk cache, or compiles it (a few seconds) when the cache is empty or
    stale.  Returns ``{"accelerator", "import_s", "first_call_s",
    "cache_dir", "error"}`` (``accelerator``: the backend's name).
    """
    t0 = time.perf_counter()
    kernel = kernel_module()
    import_s = time.perf_counter() - t0
    info = {"accelerator": backend(), "import_s": import_s, "first_call_s": 0.0, "cache_dir": None,
            "error": _STATE["error"]}
    if kernel is None:
        return info
    t1 = time.perf_counter()
    for dtype in (np.int32, np.int64):
        rng = np.random.default_rng(0)
        s = rng.integers(0, 50, (2, 2, 40)).astype(dtype)
        v = rng.integers(0, 50, (2, 3, 10)).astype(dtype)
        t_s = np.arange(40, dtype=np.int64) * 1_000_000
        t_v = np.arange(10, dtype=np.int64) * 4_000_000
        cell_quantities(s, t_s, v, t_v, 1000.0, 250.0)
        cell_quantities(s, np.stack([t_s, t_s]), v, np.stack([t_v, t_v]), 1000.0, 250.0)
        cell_bounds(s)
        kernel.central_moments(s.reshape(4, 40), np.empty((4, 5)))  # the statistics feature group
    kernel.power_spectrum(np.zeros((2, 8)), np.ones(4), np.empty((2, 4)))  # the bands and statistics groups
    kernel.band_moments(np.zeros((2, 4)), np.ones(4), np.zeros(1, dtype=np.int64), np.full(1, 4, dtype=np.int64),
                        np.empty((2, 1, 3)))  # the bands group
    one = np.ones(1, dtype=np.int64)  # the rocket group: one kernel, one dilation, one bias
    kernel.rocket_ppv(np.zeros((1, 1, 9)), one, one, one, np.zeros(1, dtype=np.int64), np.zeros(1),
                      np.array([[0, 1, 2]], dtype=np.int64), np.empty((1, 1)))
    # the window node's intake (windowing.INTAKE_DTYPES; int64 stamps, runs and rows, bool validity)
    rows = np.zeros(1, dtype=np.int64)
    counts = np.ones(1, dtype=np.int64)
    t = np.zeros(1, dtype=np.int64)
    flags = np.zeros(1, dtype=bool)
    kernel.runs_in_order(t, counts, rows, 1, flags, t, flags, t)
    kernel.explore_runs(rows, counts, t, np.zeros(1), 1.0, np.zeros(1, dtype=np.int64), np.zeros(1, dtype=bool),
                        np.zeros((1, 1), dtype=np.int64), np.zeros((1, 1, 1)), np.zeros(1, dtype=np.int64),
                        np.ones(1, dtype=np.int64), 1, np.zeros(1))
    i64 = np.zeros(1, dtype=np.int64)
    kernel.cut_rows(np.zeros((1, 1), dtype=np.int64), np.zeros((1, 1), dtype=bool), i64, i64, 0, 1, 2,
                    i64.copy(), i64.copy(), i64.copy(), i64.copy())  # the window cut (windowing.Windower._make_window)
    kernel.trim_rows(np.zeros((1, 1), dtype=np.int64), i64.copy(), i64.copy(), np.zeros(1, dtype=bool), 0)  # trims

    def buffer(dtype, lo=False):  # a row buffer's arrays (windowing._buffer_args): one row, room for two samples
        return (np.zeros((1, 2), dtype=np.int64), np.zeros((1, 1, 2), dtype=dtype), np.zeros((1, 2), dtype=bool)) \
            + ((np.zeros(1, dtype=np.int64),) if lo else ()) + (np.zeros(1, dtype=np.int64), np.zeros(1, dtype=np.int64),
                                                                np.zeros(1, dtype=bool), np.zeros(1, dtype=np.int64))
    # a skin body part's message in one call (windowing._FUSED_DTYPES: int32 counts)
    one32 = np.ones((1, 1), dtype=np.int32)
    kernel.add_part_runs(rows, counts, counts.copy(), t, one32, flags, False, t.copy(), one32.copy(), flags, False,
                         np.zeros((1, 1)), True, np.zeros(1), *buffer(np.int32), *buffer(np.int32),
                         *buffer(np.float64), *buffer(np.float64, lo=True), True, 1.0, np.zeros(1, dtype=np.int64),
                         np.zeros(1, dtype=bool), 1, np.zeros(1))
    # a body part's message converted (nodes.conversions: rclpy's array fields as writeable contiguous views)
    one_u32, one_f64 = np.ones(1, dtype=np.uint32), np.zeros(3)
    kernel.skin_part_arrays(one_u32, one_u32, one_f64, np.zeros(1, dtype=np.int16), np.zeros(1, dtype=np.int16),
                            np.zeros(1, dtype=np.int16), t, np.zeros(3, dtype=np.uint16), t, 0, 1.0, -32768, 65535,
                            np.zeros(1, dtype=np.uint16), one_f64[:1].copy(), np.zeros(1, dtype=np.int64))
    # its runs checked against the served cells (streams.skin_parts.RunChecker)
    kernel.check_runs(t, one_u32, one_u32, t, t, 0, np.zeros(1, dtype=bool), t.copy(), np.zeros(1, dtype=bool),
                      np.zeros(7, dtype=np.int64))
    for dtype in (np.int32, np.int64, np.float64):
        kernel.append_runs(np.zeros((1, 1), dtype=np.int64), np.zeros((1, 1, 1), dtype=dtype),
                           np.zeros((1, 1), dtype=bool), np.zeros(1, dtype=np.int64), np.zeros(1, dtype=np.int64),
                           np.zeros(1, dtype=bool), rows, counts, t, np.zeros((1, 1), dtype=dtype), flags, True)
    warm_up_codecs(kernel)
    warm_up_stream(kernel)
    warm_up_contact(kernel)
    warm_up_cdr(kernel)
    info["first_call_s"] = time.perf_counter() - t1
    info["cache_dir"] = kernel.CACHE_DIR
    return info


def warm_up_codecs(kernel: ModuleType) -> None:
    """Load (or compile) the CAN decoder's and the sequence tracker's compiled passes (``decode_can_rows``,
    ``track_forward``) in the one variant their callers use: a frame array's fields are strided views, times
    and periods int64 and float64 arrays.  :func:`warm_up` calls it for ``make setup``; a skin driver calls it
    (``codecs.skin_can.load_compiled``) before it opens its bus."""
    byte, word = np.zeros(4, dtype=np.uint8)[::2], np.zeros(4, dtype=np.uint32)[::2]
    i64 = np.zeros(2, dtype=np.int64)
    kernel.decode_can_rows(byte, word, byte, np.zeros((4, 8), dtype=np.uint8)[::2], np.zeros(4)[::2],
                           np.ones(1, dtype=bool), 6, 1, 0, np.zeros(16, dtype=np.int64), np.zeros(16),
                           np.empty(2, dtype=np.int8), np.empty((2, 3), dtype=np.int64), i64, i64, i64, np.empty(2),
                           i64)
    kernel.track_forward(i64, i64, i64, np.ones(2), 256, np.zeros(1, dtype=bool), np.zeros(1, dtype=np.int64),
                         np.zeros(1, dtype=np.int64), np.zeros(1, dtype=np.int64), np.zeros(1, dtype=bool),
                         np.empty(2, dtype=np.int8), np.empty(2, dtype=np.int64), np.empty(2, dtype=np.int64),
                         np.empty(2, dtype=np.int64), np.empty(2, dtype=np.int64))


def warm_up_stream(kernel: ModuleType) -> None:
    """Load (or compile) a skin stream's stamping pass (``skin_stamp_add``) in the variant
    :meth:`~tactile_descriptors_ros.streams.skin.SkinStream._add_compiled` calls: C-contiguous int64, float64 and
    bool arrays.  :func:`warm_up` calls it for ``make setup``; a skin driver calls it
    (``streams.skin.load_compiled``) before it opens its bus."""
    i64, f64, b = np.zeros(1, dtype=np.int64), np.zeros(1), np.zeros(1, dtype=bool)
    given_t = np.zeros(0, dtype=np.int64)  # clock stamps made in the pass; device stamps given are the same type
    kernel.skin_stamp_add(i64, i64, i64, np.ones(1, dtype=np.int64), np.zeros((1, 3), dtype=np.int64), given_t,
                          np.ones(4), np.zeros(4, dtype=np.int64), np.zeros(4, dtype=bool), np.zeros(4, dtype=np.int64),
                          np.zeros(4, dtype=np.int64), np.zeros(4, dtype=bool), np.zeros(4, dtype=np.int64),
                          np.zeros(4, dtype=bool), np.zeros(4, dtype=np.int64), np.zeros(4, dtype=np.int64),
                          np.zeros(4, dtype=np.int64), np.zeros(4, dtype=np.int64), 0.0, 0, 0, 0, i64.copy(),
                          i64.copy(), i64.copy(), f64, 0.0, f64.copy(), i64.copy(), b, i64.copy(), b.copy(),
                          i64.copy(), b.copy(), np.zeros((1, 5), dtype=np.int64), np.zeros((1, 5, 3), dtype=np.int64),
                          i64.copy(), i64.copy(), np.empty((3, 1), dtype=np.int64), np.empty((3, 1), dtype=np.int64),
                          np.empty((3, 1, 3), dtype=np.int64), np.zeros(5, dtype=np.int64))


def warm_up_cdr(kernel: ModuleType) -> None:
    """Load (or compile) the reading and the writing of a ``SkinPartFrames``' CDR bytes (``skin_part_cdr``,
    ``skin_part_cdr_bytes``) in the variants :mod:`..codecs.cdr` calls: a C-contiguous writeable copy of the
    bytes; text as read-only bytes, the arrays C-contiguous in the dtypes it converts them to.  :func:`warm_up`
    calls it for ``make setup``; the nodes that read or write the bytes call it when they start."""
    kernel.skin_part_cdr(np.zeros(16, dtype=np.uint8))
    text = np.frombuffer(b"", dtype=np.uint8)
    i64 = np.zeros(0, dtype=np.int64)
    kernel.skin_part_cdr_bytes(0, 0, text, text, i64, i64, i64, i64, np.zeros(0), np.zeros((0, 3)), i64,
                               np.zeros((3, 0), dtype=np.int16), i64, 0.0, np.zeros((3, 0), dtype=np.uint16), i64,
                               0.0, np.zeros(0, dtype=np.uint16), 0.0)


def warm_up_contact(kernel: ModuleType) -> None:
    """Load (or compile) the contact node's sums of a body part's message (``skin_run_sums``) in the variant
    :func:`~.contact.reduce_skin_runs` calls: a ``SkinPartFrames``' dtypes, C-contiguous writeable arrays.
    :func:`warm_up` calls it for ``make setup``; a contact node serving skin cells calls it when it starts."""
    i64 = np.zeros(1, dtype=np.int64)
    kernel.skin_run_sums(i64, np.zeros((0, 3), dtype=np.uint16), np.zeros((1, 3)), np.zeros(0, dtype=np.int64), 0,
                         i64, np.zeros((3, 0), dtype=np.int16), 1.0, 65535, -32768, np.empty((3, 1)), np.empty(1),
                         np.empty((3, 1)), np.empty((3, 1)), np.empty(1), np.empty(1, dtype=np.int64),
                         np.empty(1, dtype=np.int64))


def main(argv: list[str] | None = None) -> int:
    """Compile (or load) the descriptor kernel now and say where it is cached.

    ``make setup`` runs it, so the nodes find the compiled kernel at their
    first start instead of compiling it for about 30 s.
    """
    import argparse
    import sys

    parser = argparse.ArgumentParser(prog="tactile_descriptors_ros.core.fast.main", description=main.__doc__)
    parser.parse_args(argv)
    print("descriptor kernel: compiling into its cache (about 30 s the first time) ...", file=sys.stderr, flush=True)
    info = warm_up()
    if info["cache_dir"] is None:
        print(f"descriptor kernel: reference only ({info['error'] or 'compiled backends disabled'}); "
              "nothing to compile", file=sys.stderr, flush=True)
        return 0
    print(f"descriptor kernel: ready in {info['import_s'] + info['first_call_s']:.1f} s, cached in "
          f"{info['cache_dir']}", file=sys.stderr, flush=True)
    return 0
