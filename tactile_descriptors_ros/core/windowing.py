"""Windows over streaming cell data: fixed (length, hop) or one exploration.

The window node feeds :class:`Windower` with :class:`CellChunk` objects (one
per received message) and asks it for finished windows.  Everything runs on
the *sensor time stamps*, never the wall clock, so live data, simulated time
and replayed bags give the same windows.

* Fixed mode: windows ``[end - length, end)`` whose ends lie on one grid of
  stamp time, :data:`GRID_MARGIN_PERIODS` vibration sample periods before a
  whole multiple of ``hop`` (:func:`first_fixed_start`); the first is the
  first window after the first sample.  A window is emitted once every live
  cell has sent vibration data of a later time (plus ``lateness_s``): cells
  whose messages travel separately (one per body part) are all in before it
  is cut, whatever order they arrive in.  A cell more than
  :data:`WATERMARK_STALL_S` behind the most recent one is not waited for.
* Exploration mode (what the paper evaluates): an exploration starts when
  any cell's normal force reaches F_t (contact onset) and ends when every
  cell has stayed below the release threshold for ``release_s`` (release) or
  when it reaches ``max_duration_s``; shorter than ``min_duration_s`` it is
  dropped and counted.  Each exploration gets an id (1, 2, ...) that labels
  refer to.

Faults are counted, never hidden: chunks older than data already received
(out of order) or repeating a time stamp (duplicates) are dropped and
counted; a time jump backwards by more than ``clock_jump_s`` resets the
cell's buffer and is counted as a clock jump.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np

from ..errors import ConfigError, SignalError
from . import fast
from .aggregation import CellSignals, CellStacks
from .robot import RobotDescription

__all__ = ["CellChunk", "PartChunk", "Window", "Windower", "SampleStream", "GAP_PERIODS", "WATERMARK_STALL_S", "BUFFER_HEADROOM",
           "BUFFER_SLACK_S", "GRID_MARGIN_PERIODS", "first_fixed_start", "grid_margin_ns", "rehearsal_window"]

#: Exploration mode judges contact only up to the time every cell has sent
#: force data for (the watermark), so the order in which cells' messages
#: arrive cannot change onset or release; a cell silent for longer than this
#: behind the most recent one (unplugged, dead) no longer holds it back.
WATERMARK_STALL_S = 0.5

#: Force samples a cell may have after the time its smoothed force is asked
#: for, beyond the ``smooth_s`` looked at (:meth:`Windower._forces_at`): the
#: watermark trails a cell's newest sample by about one message (10 ms, 2-3
#: samples at the skin's 250 Hz); a cell further ahead is looked at alone.
FORCE_TAIL_EXTRA = 8

#: A cell's buffers are sized when its first chunk arrives, from its cell
#: type's rates, for the longest span the windower keeps plus
#: :data:`BUFFER_SLACK_S` (the chunks of one drained batch), times this
#: headroom: the kept samples are moved down once per third of a buffer, and
#: the buffer never has to grow (growing by doubling left the window node
#: with buffers 2-4 times the data, filled over minutes).
BUFFER_HEADROOM = 1.5
#: Seconds of samples a buffer holds beyond the retained span [s].
BUFFER_SLACK_S = 2.0

#: Samples older than the kept span are dropped once the span's start has moved by this much [ns] (not at
#: every poll: a poll then costs nothing per cell).
TRIM_STEP_NS = 100_000_000

#: Fixed windows end this many vibration sample periods (of the robot's slowest vibration stream) before a
#: whole multiple of the hop in stamp time.  The skin driver cuts its messages on a grid of ``batch_s`` in
#: stamp time (:mod:`..streams.skin`), and a hop is a whole number of batches, so every window then ends
#: just before a batch ends: the batch that holds the window's last samples also holds a vibration sample
#: after its end, and the window is cut as soon as that batch arrives.  A window ending on a batch boundary
#: waited a whole batch more (10 ms in the NAO graph) for the next batch's first sample.  One and a half
#: periods, not one: with one, a cell whose samples fall on the grid has a sample right at a window's end,
#: and a stamp a few microseconds early (its clock estimate moves, :mod:`..streams.clock`) puts that sample
#: inside the window, which then waits for the next batch again.
GRID_MARGIN_PERIODS = 1.5

#: A fixed window's samples are cut ahead (:meth:`Windower.cut_fixed_ahead`) once every live cell has sent
#: data to within this much of its end [s]: about the last batches, whose samples are then all that is left to
#: copy when the window closes.
CUT_AHEAD_S = 0.05

#: A cell whose vibration samples leave a hole longer than this many sample
#: periods inside a window (or at its edges) is marked ``gap`` and counted.
GAP_PERIODS = 3.0


def first_fixed_start(first_ns: int, length_ns: int, hop_ns: int, margin_ns: int) -> int:
    """The start of the first fixed window wholly at or after ``first_ns`` [ns].

    Fixed windows end ``margin_ns`` before a whole multiple of ``hop_ns``
    (:data:`GRID_MARGIN_PERIODS`), so the same stamps give the same windows in
    every window node and every replay, whenever each one started.
    """
    n = -(-(int(first_ns) + length_ns + margin_ns) // hop_ns)  # ceil
    return n * hop_ns - margin_ns - length_ns


def grid_margin_ns(robot: RobotDescription) -> int:
    """How long before a whole multiple of the hop a robot's fixed windows end [ns]: :data:`GRID_MARGIN_PERIODS`
    sample periods of its slowest vibration stream."""
    slowest_hz = min((robot.cell_types[p.cell_type].vibration.rate_hz for p in robot.body_parts), default=1e3)
    return int(round(GRID_MARGIN_PERIODS * 1e9 / slowest_hz))


@dataclass
class CellChunk:
    """Samples of one cell from one message.

    Attributes
    ----------
    vibration : numpy.ndarray, shape (n_s, n)
    vibration_t_ns : numpy.ndarray of int64, shape (n,)
    deformation : numpy.ndarray, shape (n_v, m)
    deformation_t_ns : numpy.ndarray of int64, shape (m,)
    force_n : numpy.ndarray, shape (k,)
        Normal force in newtons (NaN where invalid).
    force_t_ns : numpy.ndarray of int64, shape (k,)
    vibration_valid, deformation_valid : numpy.ndarray of bool, optional
        Per-sample validity (False for parity errors, lost words).
    extra : numpy.ndarray, shape (n_extra, m), optional
        The cell type's extra channels (float, NaN where missing), one value
        per deformation sample; ``None`` when the message carries none (all
        missing).
    deformation_tare : numpy.ndarray, shape (n_v,), optional
        The deformation channels' tare in counts, as the driver reports it
        (the window keeps the latest; the ``levels`` group subtracts it).
    """

    vibration: np.ndarray
    vibration_t_ns: np.ndarray
    deformation: np.ndarray
    deformation_t_ns: np.ndarray
    force_n: np.ndarray
    force_t_ns: np.ndarray
    vibration_valid: np.ndarray | None = None
    deformation_valid: np.ndarray | None = None
    extra: np.ndarray | None = None
    deformation_tare: np.ndarray | None = None


@dataclass
class PartChunk:
    """Samples of several cells from one message, as runs: run ``i`` is cell ``cell_ids[i]``'s samples.

    Every sample array is the concatenation of the runs' samples in run
    order; ``vibration_count[i]`` and ``deformation_count[i]`` say how many
    each run holds (force samples ride on the deformation stamps, one each).
    :meth:`Windower.add_part` takes it with a few array operations per
    message; :meth:`chunks` gives the same samples as one :class:`CellChunk`
    per run (what :meth:`Windower.add_many` takes, the reference).

    Attributes
    ----------
    cell_ids, vibration_count, deformation_count : numpy.ndarray of int64, shape (n_runs,)
    vibration : numpy.ndarray, shape (n_s, sum(vibration_count))
    vibration_t_ns : numpy.ndarray of int64
    deformation : numpy.ndarray, shape (n_v, sum(deformation_count))
    deformation_t_ns : numpy.ndarray of int64
    force_n : numpy.ndarray of float64, shape (sum(deformation_count),)
    vibration_valid, deformation_valid : numpy.ndarray of bool, optional
    extra : numpy.ndarray, shape (n_extra, sum(deformation_count)), optional
    deformation_tare : numpy.ndarray, shape (n_runs, n_v), optional
    """

    cell_ids: np.ndarray
    vibration_count: np.ndarray
    deformation_count: np.ndarray
    vibration: np.ndarray
    vibration_t_ns: np.ndarray
    deformation: np.ndarray
    deformation_t_ns: np.ndarray
    force_n: np.ndarray
    vibration_valid: np.ndarray | None = None
    deformation_valid: np.ndarray | None = None
    extra: np.ndarray | None = None
    deformation_tare: np.ndarray | None = None

    def __len__(self) -> int:
        return int(len(self.cell_ids))

    def take(self, runs: np.ndarray) -> PartChunk:
        """The runs selected by a boolean mask, as a new chunk (arrays copied only where runs are left out)."""
        runs = np.asarray(runs, bool)
        if runs.all():
            return self
        a = np.repeat(runs, self.vibration_count)
        d = np.repeat(runs, self.deformation_count)
        return PartChunk(
            self.cell_ids[runs], self.vibration_count[runs], self.deformation_count[runs],
            self.vibration[:, a], self.vibration_t_ns[a], self.deformation[:, d], self.deformation_t_ns[d],
            self.force_n[d], None if self.vibration_valid is None else self.vibration_valid[a],
            None if self.deformation_valid is None else self.deformation_valid[d],
            None if self.extra is None else self.extra[:, d],
            None if self.deformation_tare is None else self.deformation_tare[runs])

    def chunks(self) -> list[tuple[int, CellChunk]]:
        """One :class:`CellChunk` per run, in run order (slices of these arrays)."""
        out = []
        a_end = np.cumsum(self.vibration_count).tolist()
        d_end = np.cumsum(self.deformation_count).tolist()
        a0 = d0 = 0
        for i, cid in enumerate(np.asarray(self.cell_ids).tolist()):
            a1, d1 = a_end[i], d_end[i]
            out.append((int(cid), CellChunk(
                vibration=self.vibration[:, a0:a1], vibration_t_ns=self.vibration_t_ns[a0:a1],
                deformation=self.deformation[:, d0:d1], deformation_t_ns=self.deformation_t_ns[d0:d1],
                force_n=self.force_n[d0:d1], force_t_ns=self.deformation_t_ns[d0:d1],
                vibration_valid=None if self.vibration_valid is None else self.vibration_valid[a0:a1],
                deformation_valid=None if self.deformation_valid is None else self.deformation_valid[d0:d1],
                extra=None if self.extra is None else self.extra[:, d0:d1],
                deformation_tare=None if self.deformation_tare is None else self.deformation_tare[i])))
            a0, d0 = a1, d1
        return out


@dataclass
class Window:
    """One finished window, ready for :func:`~.aggregation.describe_window`.

    ``stacks``: when every cell of the robot is in the window, clean, with
    as many samples as the others, its cells' arrays are the rows of shared
    arrays (:class:`~.aggregation.CellStacks`, for ``describe_window``'s
    ``stacks``), else None.
    """

    start_ns: int
    end_ns: int
    exploration_id: int
    mode: str
    cells: dict[int, CellSignals] = field(default_factory=dict)
    stacks: CellStacks | None = None


class SampleStream:
    """A trimmable buffer of time-stamped multichannel samples, sized up front.

    Samples live in preallocated arrays between ``_lo`` and ``_hi``;
    trimming moves ``_lo`` (no copy) and appending moves the kept samples
    down to the start when the end is reached, so the cost per message is a
    few slice assignments.  The arrays grow (to twice what is needed) only
    when the kept samples would fill more than three quarters of them, i.e.
    when more is kept than the capacity was sized for.  The last stamp is
    kept as a Python int (it is read for every message).

    Parameters
    ----------
    n_channels : int
    dtype : numpy dtype
    capacity : int, default 256
        Samples the arrays hold from the start.
    touch : bool, default False
        Write the arrays once at creation, so their memory is resident from
        the start instead of page by page as samples first reach it.
    """

    def __init__(self, n_channels: int, dtype: np.dtype, capacity: int = 256, touch: bool = False) -> None:
        self.n_channels = int(n_channels)
        cap = max(int(capacity), 1)
        self._t = np.empty(cap, dtype=np.int64)
        self._v = np.empty((self.n_channels, cap), dtype=dtype)
        self._ok = np.empty(cap, dtype=bool)
        if touch:
            for a in (self._t, self._v, self._ok):
                a.fill(0)
        self._lo = 0
        self._hi = 0
        self._last: int | None = None

    def __len__(self) -> int:
        return self._hi - self._lo

    @property
    def last_t_ns(self) -> int | None:
        return self._last

    def append(self, t_ns: np.ndarray, values: np.ndarray, valid: np.ndarray | None = None) -> None:
        n = t_ns.shape[0]
        if values.shape != (self.n_channels, n):
            raise SignalError(f"expected samples of shape ({self.n_channels}, {n}), got {values.shape}")
        if n == 0:
            return
        hi = self._hi
        end = hi + n
        if end > self._t.shape[0]:
            self._compact(n)
            hi = self._hi
            end = hi + n
        self._t[hi:end] = t_ns
        self._v[:, hi:end] = values
        self._ok[hi:end] = True if valid is None else valid
        self._hi = end
        self._last = int(self._t[end - 1])

    @property
    def capacity(self) -> int:
        """Samples the arrays hold."""
        return int(self._t.shape[0])

    @property
    def nbytes(self) -> int:
        """Bytes of the arrays."""
        return int(self._t.nbytes + self._v.nbytes + self._ok.nbytes)

    def _compact(self, extra: int) -> None:
        size = self._hi - self._lo
        cap = self._t.shape[0]
        if size + extra > cap - cap // 4:
            cap = max(2 * cap, 2 * (size + extra))
            t = np.empty(cap, dtype=np.int64)
            v = np.empty((self.n_channels, cap), dtype=self._v.dtype)
            ok = np.empty(cap, dtype=bool)
        else:  # room enough once the trimmed head is dropped: move down in place
            t, v, ok = self._t, self._v, self._ok
        t[:size] = self._t[self._lo:self._hi]
        v[:, :size] = self._v[:, self._lo:self._hi]
        ok[:size] = self._ok[self._lo:self._hi]
        self._t, self._v, self._ok, self._lo, self._hi = t, v, ok, 0, size

    def trim_before(self, t_ns: int) -> None:
        """Drop samples older than ``t_ns``."""
        if self._hi == self._lo or t_ns <= self._t[self._lo]:
            return  # nothing older than t_ns
        t = self._t[self._lo:self._hi]
        i = int(np.searchsorted(t, t_ns, side="left"))
        self._lo += i
        if self._lo == self._hi:
            self._last = None

    def clear(self) -> None:
        self._lo = self._hi = 0
        self._last = None

    def between(self, start_ns: int, end_ns: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Samples with ``start <= t < end``."""
        t = self._t[self._lo:self._hi]
        i = int(np.searchsorted(t, start_ns, side="left"))
        j = int(np.searchsorted(t, end_ns, side="left"))
        sl = slice(self._lo + i, self._lo + j)
        return self._t[sl].copy(), self._v[:, sl].copy(), self._ok[sl].copy()


class _RowBuffer:
    """The samples of several streams (rows: the cells of one body part) in one set of 2-D arrays.

    Row ``r`` holds its samples between ``lo[r]`` and ``hi[r]`` of ``t[r]``,
    ``v[:, r]`` (channels x capacity) and ``ok[r]``, as a :class:`SampleStream`
    holds its own; :class:`_RowView` gives one row the :class:`SampleStream`
    interface.  :meth:`append_runs` writes a whole message -- several runs,
    one row each -- with a few array operations, whatever the number of
    rows: the intake of a body part costs per message, not per cell.  Rows
    are moved down (each on its own, once per third of the capacity) or the
    arrays grow only when a row reaches the end.
    """

    def __init__(self, n_rows: int, n_channels: int, dtype: np.dtype, capacity: int, touch: bool = False) -> None:
        cap = max(int(capacity), 1)
        self.n_channels = int(n_channels)
        self.t = np.empty((n_rows, cap), dtype=np.int64)
        self.v = np.empty((self.n_channels, n_rows, cap), dtype=dtype)  # channel-major: v[ch] is (rows, capacity)
        self.ok = np.empty((n_rows, cap), dtype=bool)
        if touch:
            for a in (self.t, self.v, self.ok):
                a.fill(0)
        self.lo = np.zeros(n_rows, np.int64)
        self.hi = np.zeros(n_rows, np.int64)
        self._plan: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # the last append_runs' positions
        self.last = np.zeros(n_rows, np.int64)  # newest stamp of each row (valid where ``has``)
        self.has = np.zeros(n_rows, bool)
        self.added = np.zeros(n_rows, np.int64)  # samples appended to each row so far (Windower._held_since)
        #: Changes with every call that may move ``lo``, ``hi`` or ``last``: a body part whose force buffer kept
        #: its version kept its rows holding samples and their newest stamps (:meth:`_Part.held_force`).
        self.version = 0

    @property
    def capacity(self) -> int:
        return int(self.t.shape[1])

    @property
    def nbytes(self) -> int:
        return int(self.t.nbytes + self.v.nbytes + self.ok.nbytes)

    def _make_room(self, need: np.ndarray) -> None:
        """Room for ``need[r]`` more samples in every row: rows moved down, or all arrays grown."""
        self.version += 1
        cap = self.capacity
        size = self.hi - self.lo
        if np.any(size + need > cap - cap // 4):
            new = int(max(2 * cap, 2 * int(np.max(size + need))))
            n = self.t.shape[0]
            t = np.empty((n, new), np.int64)
            v = np.empty((self.n_channels, n, new), self.v.dtype)
            ok = np.empty((n, new), bool)
        else:  # room enough once the trimmed heads are dropped: move the rows that need it down in place
            t, v, ok = self.t, self.v, self.ok
        full = np.flatnonzero(self.hi + need > cap) if t is self.t else np.arange(self.t.shape[0])
        for r in full.tolist():
            lo, hi = int(self.lo[r]), int(self.hi[r])
            t[r, :hi - lo] = self.t[r, lo:hi]
            v[:, r, :hi - lo] = self.v[:, r, lo:hi]
            ok[r, :hi - lo] = self.ok[r, lo:hi]
            self.lo[r], self.hi[r] = 0, hi - lo
        self.t, self.v, self.ok = t, v, ok

    def append(self, row: int, t_ns: np.ndarray, values: np.ndarray, valid: np.ndarray | None = None) -> None:
        """Samples of one row (as :meth:`SampleStream.append`)."""
        n = t_ns.shape[0]
        if values.shape != (self.n_channels, n):
            raise SignalError(f"expected samples of shape ({self.n_channels}, {n}), got {values.shape}")
        if n == 0:
            return
        self.version += 1
        if int(self.hi[row]) + n > self.capacity:
            need = np.zeros(self.t.shape[0], np.int64)
            need[row] = n
            self._make_room(need)
        hi = int(self.hi[row])
        self.t[row, hi:hi + n] = t_ns
        self.v[:, row, hi:hi + n] = values
        self.ok[row, hi:hi + n] = True if valid is None else valid
        self.hi[row] = hi + n
        self.added[row] += n
        self.last[row] = t_ns[n - 1]
        self.has[row] = True

    def append_runs(self, rows: np.ndarray, counts: np.ndarray, t_ns: np.ndarray, values: np.ndarray,
                    valid: np.ndarray | None = None, like: _RowBuffer | None = None) -> None:
        """Runs of samples, run ``i`` (``counts[i]`` samples, concatenated in run order) to row ``rows[i]``.

        Every row takes at most one run; ``values`` is (channels, total
        samples).  ``like``: a buffer that took the same runs just before
        with the same row ends and capacity (its sample positions are reused).
        """
        total = int(t_ns.shape[0])
        if values.shape != (self.n_channels, total):
            raise SignalError(f"expected samples of shape ({self.n_channels}, {total}), got {values.shape}")
        if total == 0:
            return
        self.version += 1
        if self._append_compiled(rows, counts, t_ns, values, valid):
            return
        if like is not None and like._plan is not None and like.capacity == self.capacity \
                and np.array_equal(like._plan[2], self.hi):
            flat, need, _ = like._plan
        else:
            n_rows, cap = self.t.shape
            need = np.zeros(n_rows, np.int64)
            need[rows] = counts
            if np.any(self.hi + need > cap):
                self._make_room(need)
                cap = self.t.shape[1]
            # one flat index per sample (row * capacity + column): a scatter, whatever the number of rows
            flat = np.repeat(rows * cap + self.hi[rows] - (np.cumsum(counts) - counts), counts) + np.arange(total)
        self._plan = (flat, need, self.hi.copy())
        self.t.reshape(-1)[flat] = t_ns
        self.ok.reshape(-1)[flat] = True if valid is None else valid
        if self.n_channels:
            self.v.reshape(self.n_channels, -1)[:, flat] = values
        self.hi += need
        self.added += need
        has = counts > 0  # the newest stamp of each row: the last sample of its run
        self.last[rows[has]] = t_ns[np.cumsum(counts)[has] - 1]
        self.has[rows[has]] = True

    def _append_compiled(self, rows: np.ndarray, counts: np.ndarray, t_ns: np.ndarray, values: np.ndarray,
                         valid: np.ndarray | None) -> bool:
        """:meth:`append_runs` by the compiled intake; False (nothing written) where it does not serve."""
        kernel = _intake_kernel()
        if kernel is None or values.dtype != self.v.dtype or values.dtype not in _INTAKE_DTYPES:
            return False
        if not values.flags.c_contiguous:  # e.g. a message's force samples, stored per sample (3, n) transposed
            values = np.ascontiguousarray(values)
        if valid is None:
            arrays = (values,)
        elif isinstance(valid, np.ndarray) and valid.dtype == np.bool_:
            arrays = (values, valid)
        else:
            return False
        if not _compiled_args(rows, counts, t_ns, *arrays):
            return False
        if not kernel.append_runs(self.t, self.v, self.ok, self.hi, self.last, self.has, rows, counts, t_ns, values,
                                  _NO_VALID if valid is None else valid, valid is not None):
            return False  # a row out of room: the numpy path makes room
        self.added[rows] += counts  # every row takes at most one run
        self._plan = None  # no positions to share: a buffer given this one as ``like`` computes its own
        return True

    def cut(self, kernel, start_ns: int, end_ns: int, scan: int = 2) -> np.ndarray:
        """Every row's samples with ``start <= t < end``: rows ``first``, ``stop`` (positions), ``n_bad`` (invalid
        samples among them) and ``widest`` (longest step between the valid ones, ``start`` and ``end`` included)
        of a (4, rows) array, from the compiled backend's :func:`.numba_kernel.cut_rows`; ``scan`` as there
        (1: ``widest`` is 0; 0: ``n_bad`` too)."""
        out = np.empty((4, self.lo.size), dtype=np.int64)
        kernel.cut_rows(self.t, self.ok, self.lo, self.hi, start_ns, end_ns, scan, out[0], out[1], out[2], out[3])
        return out

    def added_inside(self, before: np.ndarray, start_ns: int, end_ns: int) -> bool:
        """Whether any sample appended since :attr:`added` was ``before`` lies in ``[start_ns, end_ns)``.

        Appended samples are a row's newest (moving rows down or growing
        keeps their order, trimming drops the oldest), so each row's are its
        last ``added - before``; looked at all at once, in whatever order
        their stamps came."""
        new = self.added - before
        rows = np.flatnonzero(new)
        if not rows.size:
            return False
        new, hi = new[rows], self.hi[rows]
        if np.any(new > hi - self.lo[rows]):  # fewer held than appended: trimmed since (not in an open window)
            return True
        at = (hi - new)[:, None] + np.arange(int(new.max()))[None, :]
        t = self.t[rows[:, None], np.minimum(at, (hi - 1)[:, None])]
        return bool(np.any((at < hi[:, None]) & (t >= start_ns) & (t < end_ns)))

    def tails(self, rows: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The newest ``k`` samples of each of ``rows`` as 2-D arrays: stamps, first channel's values, and
        which are held (a row with fewer than ``k`` shows other samples, or its first, where it has none)."""
        idx = (self.hi[rows] - k)[:, None] + np.arange(k)[None, :]
        held = idx >= self.lo[rows][:, None]
        idx = np.maximum(idx, 0)
        return self.t[rows[:, None], idx], self.v[0][rows[:, None], idx], held

    def trim_before(self, t_ns: int) -> None:
        """Drop every row's samples older than ``t_ns`` (in one compiled pass where the intake is compiled:
        :func:`.numba_kernel.trim_rows`; the buffer's own arrays are its one compiled variant's layout)."""
        kernel = _intake_kernel()
        if kernel is not None:
            if kernel.trim_rows(self.t, self.lo, self.hi, self.has, int(t_ns)):
                self.version += 1
            return
        live = np.flatnonzero(self.hi > self.lo)
        if not live.size:
            return
        old = live[self.t[live, self.lo[live]] < t_ns]
        if old.size:
            self.version += 1
        for r in old.tolist():
            lo, hi = int(self.lo[r]), int(self.hi[r])
            lo += int(np.searchsorted(self.t[r, lo:hi], t_ns, side="left"))
            self.lo[r] = lo
            if lo == hi:
                self.has[r] = False

    def clear(self, row: int) -> None:
        self.version += 1
        self.lo[row] = self.hi[row] = 0
        self.has[row] = False


class _RowView:
    """One row of a :class:`_RowBuffer` with the interface of a :class:`SampleStream`."""

    __slots__ = ("buf", "row")

    def __init__(self, buf: _RowBuffer, row: int) -> None:
        self.buf = buf
        self.row = row

    @property
    def n_channels(self) -> int:
        return self.buf.n_channels

    @property
    def _t(self) -> np.ndarray:
        return self.buf.t[self.row]

    @property
    def _v(self) -> np.ndarray:
        return self.buf.v[:, self.row]

    @property
    def _ok(self) -> np.ndarray:
        return self.buf.ok[self.row]

    @property
    def _lo(self) -> int:
        return int(self.buf.lo[self.row])

    @property
    def _hi(self) -> int:
        return int(self.buf.hi[self.row])

    def __len__(self) -> int:
        return int(self.buf.hi[self.row] - self.buf.lo[self.row])

    @property
    def last_t_ns(self) -> int | None:
        return int(self.buf.last[self.row]) if self.buf.has[self.row] else None

    @property
    def capacity(self) -> int:
        return self.buf.capacity

    @property
    def nbytes(self) -> int:
        """This row's share of its buffer's bytes."""
        return self.buf.nbytes // self.buf.t.shape[0]

    def append(self, t_ns: np.ndarray, values: np.ndarray, valid: np.ndarray | None = None) -> None:
        self.buf.append(self.row, t_ns, values, valid)

    def clear(self) -> None:
        self.buf.clear(self.row)

    def trim_before(self, t_ns: int) -> None:
        buf, r = self.buf, self.row
        lo, hi = int(buf.lo[r]), int(buf.hi[r])
        if hi == lo or t_ns <= buf.t[r, lo]:
            return
        lo += int(np.searchsorted(buf.t[r, lo:hi], t_ns, side="left"))
        buf.lo[r] = lo
        buf.version += 1
        if lo == hi:
            buf.has[r] = False

    def between(self, start_ns: int, end_ns: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Samples with ``start <= t < end`` (copies)."""
        buf, r = self.buf, self.row
        lo, hi = int(buf.lo[r]), int(buf.hi[r])
        t = buf.t[r, lo:hi]
        i = lo + int(np.searchsorted(t, start_ns, side="left"))
        j = lo + int(np.searchsorted(t, end_ns, side="left"))
        return buf.t[r, i:j].copy(), buf.v[:, r, i:j].copy(), buf.ok[r, i:j].copy()


class _Part:
    """The sample buffers of one body part's cells: one row per cell of the robot description's part."""

    def __init__(self, cell_ids: list[int], n_s: int, n_v: int, dtype_s: np.dtype, dtype_v: np.dtype, n_extra: int,
                 capacity: tuple[int, int, int], smooth_k: int) -> None:
        cap_s, cap_v, cap_f = capacity
        n = len(cell_ids)
        self.cell_ids = list(cell_ids)
        self.row = {cid: i for i, cid in enumerate(cell_ids)}
        self.ids = np.array(cell_ids, np.int64)
        self.smooth_k = int(smooth_k)  # force samples looked at for a cell's latest smoothed force
        self.last_force = np.zeros(n)  # each cell's mean force over the last smooth_s
        self.hot_until = np.zeros(n, np.int64)  # last stamp of a chunk with a force at or above release
        self.hot = np.zeros(n, bool)  # hot_until is set
        self.vib = _RowBuffer(n, n_s, dtype_s, cap_s, touch=True)
        self.dfm = _RowBuffer(n, n_v, dtype_v, cap_v, touch=True)
        # extra channels ride on the deformation stamps (one value per deformation sample)
        self.extra = _RowBuffer(n, n_extra, np.float64, cap_v, touch=True) if n_extra else None
        self.force = _RowBuffer(n, 1, np.float64, cap_f, touch=True)
        #: :meth:`held_force` at ``force.version``: (version, the rows holding force samples (read-only), their
        #: newest stamps, the largest and the smallest of those)
        self._held: tuple[int, np.ndarray, np.ndarray, int, int] | None = None
        self.buffers = [b for b in (self.vib, self.dfm, self.extra, self.force) if b is not None]

    def held_force(self) -> tuple[np.ndarray, np.ndarray, int, int] | None:
        """The rows holding force samples (a read-only array), their newest stamps, the largest and the smallest
        of those; None when no row holds one.

        Worked out again only when the force buffer changed since the last call (its ``version``): a poll after
        another body part's message finds this part's rows as they were, the same array object.
        """
        buf = self.force
        if self._held is None or self._held[0] != buf.version:
            rows = np.flatnonzero(buf.hi > buf.lo)
            rows.flags.writeable = False
            last = buf.last[rows]
            last.flags.writeable = False
            self._held = (buf.version, rows, last, int(last.max()) if rows.size else 0,
                          int(last.min()) if rows.size else 0)
        _, rows, last, newest, oldest = self._held
        return (rows, last, newest, oldest) if rows.size else None


class _CellState:
    """One cell: views of its rows in its body part's buffers, its tare and contact state."""

    def __init__(self, part: _Part, row: int) -> None:
        self.part = part
        self.row = row
        self.vib = _RowView(part.vib, row)
        self.dfm = _RowView(part.dfm, row)
        self.extra = _RowView(part.extra, row) if part.extra is not None else None
        self.force = _RowView(part.force, row)
        self.tare: np.ndarray | None = None  # latest deformation tare reported

    @property
    def last_force_n(self) -> float:
        """Mean finite force over the last ``smooth_s`` of the cell's force samples (kept when none is finite)."""
        return float(self.part.last_force[self.row])

    @property
    def hot_until_ns(self) -> int | None:
        """Last stamp of a chunk with a force at or above release (None before any)."""
        return int(self.part.hot_until[self.row]) if self.part.hot[self.row] else None

    @hot_until_ns.setter
    def hot_until_ns(self, t_ns: int | None) -> None:
        self.part.hot[self.row] = t_ns is not None
        self.part.hot_until[self.row] = 0 if t_ns is None else t_ns


class Windower:
    """Cut per-cell streams into windows (fixed or exploration mode).

    Parameters
    ----------
    robot : RobotDescription
        Cells and their types; window and contact parameters default to it.
    mode : {"fixed", "exploration"}, optional
    length_s, hop_s : float, optional
        Fixed mode.
    min_duration_s, max_duration_s, release_s : float, optional
        Exploration mode.
    force_threshold_n, release_threshold_n : float, optional
        Onset (F_t) and release thresholds.
    lateness_s : float, default 0.05
        How long after a fixed window's end to wait for late cells.
    clock_jump_s : float, default 1.0
        A stamp this far behind a cell's last one is a clock jump (buffer reset).
    smooth_s : float, default 0.05
        Onset and release are judged on each cell's mean force over this long,
        not on single noisy samples.
    max_invalid_fraction : float, default 0.05
        Invalid samples (parity errors, error words) are removed from a
        cell's window and the body part is flagged ``INVALID``; a cell with a
        larger fraction of invalid samples is left out of the window entirely.
    """

    def __init__(self, robot: RobotDescription, *, mode: str | None = None, length_s: float | None = None,
                 hop_s: float | None = None, min_duration_s: float | None = None,
                 max_duration_s: float | None = None, release_s: float | None = None,
                 force_threshold_n: float | None = None, release_threshold_n: float | None = None,
                 lateness_s: float = 0.05, clock_jump_s: float = 1.0, smooth_s: float = 0.05,
                 max_invalid_fraction: float = 0.05) -> None:
        w, c = robot.window, robot.contact
        self.robot = robot
        self.mode = mode or w.mode
        if self.mode not in ("fixed", "exploration"):
            raise ConfigError(f"window mode must be 'fixed' or 'exploration', got {self.mode!r}", key="window.mode")
        self._exploration = self.mode == "exploration"
        self.length_ns = _ns(length_s if length_s is not None else w.length_s, "window.length_s")
        self.hop_ns = _ns(hop_s if hop_s is not None else w.hop_s, "window.hop_s")
        self.min_ns = _ns(min_duration_s if min_duration_s is not None else w.min_duration_s,
                          "window.min_duration_s", allow_zero=True)
        self.max_ns = _ns(max_duration_s if max_duration_s is not None else w.max_duration_s, "window.max_duration_s")
        if self.min_ns > self.max_ns:
            raise ConfigError(f"must not exceed window.max_duration_s ({self.max_ns / 1e9:g} s), got "
                              f"{self.min_ns / 1e9:g} s", key="window.min_duration_s")
        self.release_ns = _ns(release_s if release_s is not None else w.release_s, "window.release_s", allow_zero=True)
        self.onset_n = float(force_threshold_n if force_threshold_n is not None else c.force_threshold_n)
        self.release_n = float(release_threshold_n if release_threshold_n is not None else c.release_threshold_n)
        if self.release_n > self.onset_n:
            raise ConfigError(f"release threshold must not exceed the onset threshold contact.force_threshold_n "
                              f"({self.onset_n:g} N), got {self.release_n:g} N", key="contact.release_threshold_n")
        self.lateness_ns = _ns(lateness_s, "lateness_s", allow_zero=True)
        self.clock_jump_ns = _ns(clock_jump_s, "clock_jump_s")
        self.smooth_ns = _ns(smooth_s, "smooth_s", allow_zero=True)
        if not 0.0 <= float(max_invalid_fraction) <= 1.0:
            raise ConfigError(f"must be a fraction in [0, 1], got {max_invalid_fraction!r}", key="max_invalid_fraction")
        self.max_invalid_fraction = float(max_invalid_fraction)
        self.faults: Counter[str] = Counter()
        self._cells: dict[int, _CellState] = {}
        self._parts: dict[str, _Part] = {}
        # cell id -> (body part, row in its buffers), as sorted arrays for a message's runs at once
        table = sorted((c.id, k, i) for k, p in enumerate(robot.body_parts) for i, c in enumerate(p.cells))
        self._part_names = [p.name for p in robot.body_parts]
        self._ids = np.array([x[0] for x in table], np.int64)
        self._id_part = np.array([x[1] for x in table], np.int64)
        self._id_row = np.array([x[2] for x in table], np.int64)
        self._index = robot.cell_index()
        self._shapes = {cid: (len(robot.cell_types[part.cell_type].vibration.channels),
                              len(robot.cell_types[part.cell_type].deformation.channels))
                        for cid, (part, _) in self._index.items()}
        self._n_extra = {cid: len(robot.cell_types[part.cell_type].extra_channels)
                         for cid, (part, _) in self._index.items()}
        self._latest_ns: int | None = None
        self._next_start_ns: int | None = None
        self._exploration_id = 0
        self._onset_ns: int | None = None
        self._emitted_current = False
        self._released_since: int | None = None
        # the window cut_ahead cut last and each body part's buffers' ``added`` then, until the exploration closes
        self._ahead: Window | None = None
        self._ahead_marks: dict[str, list[np.ndarray]] = {}
        self._ahead_cut_faults: Counter[str] = Counter()  # the faults its cut found, counted if it is handed back
        self._head: _Head | None = None  # the next fixed window's samples cut ahead (cut_fixed_ahead)
        #: fixed windows closed from the samples :meth:`cut_fixed_ahead` cut (``used``) or cut whole although
        #: it had (``recut``: the head did not hold, or was not one set of stacks)
        self.heads: Counter[str] = Counter()
        self._head_step_ns = _common_period_ns(robot)
        self._now_ns = 0  # the time of the current exploration step
        self._swept_ns: int | None = None  # the watermark the state machine has run to
        self._swept_key: tuple | None = None  # that watermark and the settings it was run with
        self._swept_rows: list[tuple[_Part, np.ndarray]] = []  # and the live cells it was run on
        self._resumed_ns: int | None = None  # first force stamp after the last stall (no onset before it)
        # cells not stalled behind the newest (the contact judged on): (body part, its rows)
        self._live_rows: list[tuple[_Part, np.ndarray]] = []
        self._probed_onset: int | None = None  # the exploration the release was probed for
        self._trimmed_ns: int | None = None  # the horizon of the last trim
        self._jump: tuple[int, int] | None = None  # (newest before, first after) the last stall of every cell
        self._stall_ns = int(round(WATERMARK_STALL_S * 1e9))
        self.grid_margin_ns = grid_margin_ns(robot)
        self._retain_ns = max(self.length_ns, self.max_ns) + self.lateness_ns + self._stall_ns + 1_000_000_000

    # ------------------------------------------------------------- settings
    def settings(self) -> dict[str, float]:
        """The settings :meth:`retune` may change while data flows, with their current values (s and N)."""
        return {"length_s": self.length_ns / 1e9, "hop_s": self.hop_ns / 1e9, "min_duration_s": self.min_ns / 1e9,
                "max_duration_s": self.max_ns / 1e9, "release_s": self.release_ns / 1e9,
                "force_threshold_n": self.onset_n, "release_threshold_n": self.release_n,
                "lateness_s": self.lateness_ns / 1e9}

    def retune(self, dry_run: bool = False, **changes: float) -> None:
        """Change some of :meth:`settings` while running; the buffered data and the current window are kept.

        The new values are checked together with the unchanged ones, exactly
        as the constructor checks them; on an error nothing changes.  A new
        window length or hop applies from the next fixed window on, new
        thresholds from the next onset/release decision.  ``dry_run`` only
        checks.

        Raises
        ------
        ConfigError
            For an unknown setting or an invalid combination (naming it).
        """
        current = self.settings()
        unknown = sorted(set(changes) - set(current))
        if unknown:
            raise ConfigError(f"cannot retune {unknown[0]!r} (tunable: {', '.join(current)})", key=unknown[0])
        merged = {**current, **changes}
        probe = Windower(self.robot, mode=self.mode, clock_jump_s=self.clock_jump_ns / 1e9,
                         smooth_s=self.smooth_ns / 1e9, max_invalid_fraction=self.max_invalid_fraction, **merged)
        if dry_run:
            return
        for attr in ("length_ns", "hop_ns", "min_ns", "max_ns", "release_ns", "onset_n", "release_n", "lateness_ns",
                     "_retain_ns"):
            setattr(self, attr, getattr(probe, attr))
        if self._next_start_ns is not None:  # the next window on the new grid, none before the one due
            self._next_start_ns = first_fixed_start(self._next_start_ns, self.length_ns, self.hop_ns,
                                                    self.grid_margin_ns)

    # ------------------------------------------------------------------ input
    def add(self, cell_id: int, chunk: CellChunk) -> bool:
        """Buffer one chunk; return False (and count why) when it was dropped."""
        return self._ingest(cell_id, chunk, None)

    def add_many(self, items: Iterable[tuple[int, CellChunk]]) -> list[bool]:
        """Buffer several chunks in one call; the same as :meth:`add` on each, in order.

        For a window node that drains several messages at once (e.g. all
        ``SkinCellFrame`` s of a body part received in one batch): the
        checks that :meth:`add` makes per message with small numpy calls
        (stamps strictly increasing) are made once over all chunks, so the
        cost per chunk is a few slice assignments into the cell's buffers.
        Call :meth:`poll` afterwards, as after :meth:`add`.  Windows are cut
        on sensor stamps, so in fixed mode one poll per batch gives the
        windows a poll per chunk would (except for a first window started
        by a cell whose data is older than the batch's first chunk); in
        exploration mode onset and release are judged at each poll.

        Parameters
        ----------
        items : iterable of (int, CellChunk)
            ``(cell_id, chunk)`` pairs, in arrival order; a cell may appear
            more than once (its chunks in time order), cells in any order.
            A ``dict[int, CellChunk]`` 's ``.items()`` works.

        Returns
        -------
        list of bool
            Per item, whether it was buffered (False: dropped and counted in
            :attr:`faults`, exactly as :meth:`add` would).

        Raises
        ------
        SignalError
            As :meth:`add` (e.g. vibration samples and stamps of different
            lengths); the items before the offending one stay buffered.
        """
        items = list(items)
        unsorted = self._unsorted_flags(items)
        if unsorted is None:
            return [self._ingest(cid, chunk, None) for cid, chunk in items]
        return [self._ingest(cid, chunk, bad) for (cid, chunk), bad in zip(items, unsorted)]

    def add_part(self, chunk: PartChunk) -> np.ndarray:
        """Buffer the runs of one message (the cells of a body part); per run, whether it was buffered.

        Exactly :meth:`add_many` of ``chunk.chunks()`` -- the same buffers,
        faults and return values -- in a few array operations per message
        when every run is in order (each cell's stamps increasing from where
        its buffers end, no empty run, one body part): the cost of a message
        then hardly depends on its number of cells.  Any other message goes
        through :meth:`add_many` run by run, which decides every fault as
        :meth:`add` does.  Runs of cells the robot does not have are dropped
        and counted (``unknown_cell``) either way.
        """
        n = len(chunk)
        if not n:
            return np.zeros(0, bool)
        cid = np.asarray(chunk.cell_ids, np.int64)
        pos = np.minimum(np.searchsorted(self._ids, cid), self._ids.size - 1)
        known = self._ids[pos] == cid
        if not known.all():
            self.faults["unknown_cell"] += int((~known).sum())
            ok = np.zeros(n, bool)
            if known.any():
                ok[known] = self.add_part(chunk.take(known))
            return ok
        part_code = self._id_part[pos]
        if (part_code != part_code[0]).any():
            return np.array(self.add_many(chunk.chunks()), bool)
        name = self._part_names[int(part_code[0])]
        rows = self._id_row[pos]
        fused = self._add_fused(chunk, name, rows)
        if fused == _WRITTEN:
            return np.ones(n, bool)
        if fused == _RUN_BY_RUN or not self._fast_ok(chunk, int(part_code[0]), rows):
            return np.array(self.add_many(chunk.chunks()), bool)
        self._add_runs(chunk, name, rows)
        return np.ones(n, bool)

    def _add_fused(self, chunk: PartChunk, part_name: str, rows: np.ndarray) -> int | None:
        """:meth:`add_part`'s array path in one compiled call (:func:`.numba_kernel.add_part_runs`) for a body part
        that has buffers: ``_WRITTEN``, ``_RUN_BY_RUN`` (nothing written), ``_NO_ROOM`` (nothing written: the
        pass-by-pass intake makes room) or None (not served: no compiled backend, the part's first message, other
        dtypes or layouts)."""
        kernel = _intake_kernel()
        part = self._parts.get(part_name)
        if kernel is None or part is None:
            return None
        vib, dfm, f = chunk.vibration, chunk.deformation, chunk.force_n
        vc, dc, t_v, t_d = chunk.vibration_count, chunk.deformation_count, chunk.vibration_t_ns, chunk.deformation_t_ns
        vv, fv = chunk.vibration_valid, chunk.deformation_valid
        tare = chunk.deformation_tare
        if not (isinstance(vib, np.ndarray) and isinstance(dfm, np.ndarray) and isinstance(f, np.ndarray)
                and vib.dtype == part.vib.v.dtype == dfm.dtype == part.dfm.v.dtype and vib.dtype in _FUSED_DTYPES
                and f.dtype == np.float64 and vib.ndim == dfm.ndim == 2 and f.ndim == 1
                and (vv is None or (isinstance(vv, np.ndarray) and vv.dtype == np.bool_))
                and (fv is None or (isinstance(fv, np.ndarray) and fv.dtype == np.bool_))
                and (tare is None or len(tare) == rows.size)):
            return None
        ext = part.extra
        extra = _NO_EXTRA
        if ext is not None:
            extra = chunk.extra if chunk.extra is not None else np.full((ext.n_channels, t_d.size), np.nan)
            if not (isinstance(extra, np.ndarray) and extra.dtype == np.float64 and extra.ndim == 2):
                return None
        arrays = (vib, dfm, f, extra) + tuple(a for a in (vv, fv) if a is not None)
        if not _compiled_args(rows, vc, t_v, dc, t_d, *arrays) or dc.dtype != _INDEX_DTYPE \
                or t_d.dtype != _INDEX_DTYPE:
            return None
        e = ext if ext is not None else part.force  # a buffer of the right types, not written without extra
        status = kernel.add_part_runs(
            rows, vc, dc, t_v, vib, _NO_VALID if vv is None else vv, vv is not None, t_d, dfm,
            _NO_VALID if fv is None else fv, fv is not None, extra, ext is not None, f,
            *_buffer_args(part.vib), *_buffer_args(part.dfm), *_buffer_args(e), *_buffer_args(part.force, lo=True),
            self._exploration, float(self.release_n), part.hot_until, part.hot, int(self.smooth_ns), part.last_force)
        if status != _WRITTEN:
            return int(status)
        for buf in part.buffers:
            buf.version += 1
            buf._plan = None
        ids = np.asarray(chunk.cell_ids, np.int64).tolist()
        for c in ids:
            if c not in self._cells:  # a cell's first chunk of a body part that has buffers: its state
                self._new_cell(c, vib.dtype, dfm.dtype)
        self._after_runs(chunk, ids, vc, t_v)
        return _WRITTEN

    def _fast_ok(self, chunk: PartChunk, part_code: int, rows: np.ndarray) -> bool:
        """Whether :meth:`add_part` may take ``chunk`` in one piece (see there)."""
        vc = chunk.vibration_count
        dc = chunk.deformation_count
        cid0 = int(chunk.cell_ids[0])
        n_s, n_v = self._shapes[cid0]
        vib, dfm = chunk.vibration, chunk.deformation
        t_v, t_d = chunk.vibration_t_ns, chunk.deformation_t_ns
        n_a, n_d = int(vc.sum()), int(dc.sum())
        if (getattr(vib, "shape", None) != (n_s, n_a) or getattr(dfm, "shape", None) != (n_v, n_d)
                or t_v.shape != (n_a,) or t_d.shape != (n_d,) or np.shape(chunk.force_n) != (n_d,)
                or vc.shape != rows.shape or dc.shape != rows.shape or vc.min() <= 0 or dc.min() < 0):
            return False
        for valid, size in ((chunk.vibration_valid, n_a), (chunk.deformation_valid, n_d)):
            if valid is not None and np.shape(valid) != (size,):
                return False
        n_extra = self._n_extra[cid0]
        if n_extra and chunk.extra is not None and np.shape(chunk.extra) != (n_extra, n_d):
            return False
        if chunk.deformation_tare is not None and np.shape(chunk.deformation_tare)[0] != rows.size:
            return False
        part = self._parts.get(self._part_names[part_code])
        kernel = _intake_kernel()
        if kernel is not None and part is not None and _compiled_args(rows, vc, t_v) and _compiled_args(rows, dc, t_d):
            # one compiled pass each: a cell twice in the message, stamps not increasing, or a run that does
            # not start after its buffers' newest stamp sends the message run by run
            n_rows = part.vib.t.shape[0]
            return bool(kernel.runs_in_order(t_v, vc, rows, n_rows, part.vib.has, part.vib.last, part.vib.has,
                                             part.vib.last)
                        and kernel.runs_in_order(t_d, dc, rows, n_rows, part.dfm.has, part.dfm.last, part.force.has,
                                                 part.force.last))
        if np.bincount(rows).max() > 1:  # a cell twice in one message: run by run
            return False
        if not _in_order(t_v, vc, rows, None if part is None else (part.vib,)):
            return False
        return _in_order(t_d, dc, rows, None if part is None else (part.dfm, part.force))

    def _add_runs(self, chunk: PartChunk, part_name: str, rows: np.ndarray) -> None:
        """Write an in-order message (:meth:`_fast_ok`) into its body part's buffers."""
        vc = np.asarray(chunk.vibration_count, np.int64)
        dc = np.asarray(chunk.deformation_count, np.int64)
        ids = np.asarray(chunk.cell_ids, np.int64)
        vib, dfm = np.asarray(chunk.vibration), np.asarray(chunk.deformation)
        for c in ids.tolist():
            if c not in self._cells:  # a cell's first chunk (in run order, as add_many creates them)
                self._new_cell(c, vib.dtype, dfm.dtype)
        part = self._parts[part_name]
        t_v = np.asarray(chunk.vibration_t_ns, np.int64)
        t_d = np.asarray(chunk.deformation_t_ns, np.int64)
        part.vib.append_runs(rows, vc, t_v, vib, chunk.vibration_valid)
        part.dfm.append_runs(rows, dc, t_d, dfm, chunk.deformation_valid)
        if part.extra is not None:
            extra = (np.full((part.extra.n_channels, t_d.size), np.nan) if chunk.extra is None
                     else np.asarray(chunk.extra, np.float64))  # missing, never zeros: levels flags it
            part.extra.append_runs(rows, dc, t_d, extra, like=part.dfm)
        f = np.asarray(chunk.force_n, np.float64)
        part.force.append_runs(rows, dc, t_d, f[None, :], like=part.dfm)
        if self._exploration and not self._explore_compiled(part, rows, dc, t_d, f):
            with_f = np.flatnonzero(dc > 0)
            if with_f.size:
                starts = np.cumsum(dc) - dc
                peak = np.fmax.reduceat(f, starts[with_f])  # fmax: NaN never hides a touch
                hot = with_f[peak >= self.release_n]
                if hot.size:  # each cell's last such run: its last force stamp
                    rr, last_of = np.unique(rows[hot][::-1], return_index=True)
                    run = hot[::-1][last_of]
                    part.hot_until[rr] = t_d[starts[run] + dc[run] - 1]
                    part.hot[rr] = True
                self._update_last_force_rows(part, np.unique(rows[with_f]))
        self._after_runs(chunk, ids.tolist(), vc, t_v)

    def _after_runs(self, chunk: PartChunk, ids: list[int], vc: np.ndarray, t_v: np.ndarray) -> None:
        """What :meth:`add_part` keeps besides the buffers: the cells' tares and the newest stamp (and a stall's
        end, as :meth:`add_many` would find it run by run)."""
        if chunk.deformation_tare is not None:
            tare = np.array(chunk.deformation_tare, np.float64)  # one copy: messages own their arrays
            for i, c in enumerate(ids):
                self._cells[c].tare = tare[i]
        ends = np.cumsum(vc)
        firsts, lasts = t_v[ends - vc], t_v[ends - 1]
        if self._latest_ns is None:  # the first run only sets the newest stamp, as add_many's first chunk does
            self._latest_ns = int(lasts[0])
            firsts, lasts = firsts[1:], lasts[1:]
        if lasts.size:
            if int(firsts.max()) - self._latest_ns > self._stall_ns:  # rare: a stall may end in this message
                # each run against the newest stamp before it, as add_many takes them one by one
                before = np.maximum.accumulate(np.concatenate(([self._latest_ns], lasts[:-1])))
                hit = np.flatnonzero(firsts - before > self._stall_ns)
                if hit.size:
                    self._jump = (int(before[hit[-1]]), int(firsts[hit[-1]]))
            self._latest_ns = max(self._latest_ns, int(lasts.max()))

    def _explore_compiled(self, part: _Part, rows: np.ndarray, dc: np.ndarray, t_d: np.ndarray,
                          f: np.ndarray) -> bool:
        """The exploration state of :meth:`_add_runs` (hot cells, smoothed forces) by the compiled intake;
        False (nothing changed) where it does not serve."""
        kernel = _intake_kernel()
        buf = part.force
        if kernel is None or not _compiled_args(rows, dc, t_d, f) or f.dtype != np.float64:
            return False
        kernel.explore_runs(rows, dc, t_d, f, float(self.release_n), part.hot_until, part.hot, buf.t, buf.v, buf.lo,
                            buf.hi, int(self.smooth_ns), part.last_force)
        return True

    @staticmethod
    def _unsorted_flags(items: list[tuple[int, CellChunk]]) -> list[bool] | None:
        """Per item, whether its vibration stamps fail to increase strictly (one pass over all)."""
        if not items:
            return []
        try:
            ts = [np.asarray(chunk.vibration_t_ns, dtype=np.int64) for _, chunk in items]
            if any(t.ndim != 1 for t in ts):
                return None
            sizes = np.fromiter((t.shape[0] for t in ts), dtype=np.int64, count=len(ts))
            bad = np.diff(np.concatenate(ts)) <= 0
        except (TypeError, ValueError, OverflowError):
            return None  # odd input: the per-chunk checks decide (and fault) as add does
        ends = np.cumsum(sizes)
        inner = ends[:-1] - 1  # the step from one chunk's last stamp to the next chunk's first
        bad[inner[(inner >= 0) & (inner < bad.size)]] = False
        if not bad.any():
            return [False] * len(items)
        hit = np.searchsorted(ends, np.flatnonzero(bad), side="right")
        flags = np.zeros(len(items), dtype=bool)
        flags[hit] = True
        return flags.tolist()

    def _ingest(self, cell_id: int, chunk: CellChunk, unsorted: bool | None) -> bool:
        """:meth:`add`, with the stamp-order check already made when ``unsorted`` is not None."""
        shape = self._shapes.get(cell_id)
        if shape is None:
            self.faults["unknown_cell"] += 1
            return False
        vib = np.asarray(chunk.vibration)
        dfm = np.asarray(chunk.deformation)
        if vib.ndim != 2 or dfm.ndim != 2 or (vib.shape[0], dfm.shape[0]) != shape:
            self.faults["bad_shape"] += 1
            return False
        n_extra = self._n_extra[cell_id]
        extra = None
        if n_extra:
            if chunk.extra is None:
                extra = np.full((n_extra, dfm.shape[1]), np.nan)  # missing, never zeros: levels flags it
            else:
                extra = np.asarray(chunk.extra, dtype=np.float64)
                if extra.shape != (n_extra, dfm.shape[1]):
                    self.faults["bad_shape"] += 1
                    return False
        st = self._cells.get(cell_id)
        if st is None:
            st = self._new_cell(cell_id, vib.dtype, dfm.dtype)
        t_v = np.asarray(chunk.vibration_t_ns, dtype=np.int64)
        if t_v.size == 0:
            self.faults["empty"] += 1
            return False
        last = st.vib.last_t_ns
        if last is not None and t_v[0] <= last:
            if last - t_v[0] > self.clock_jump_ns:
                self.faults["clock_jump"] += 1
                for s in (st.vib, st.dfm, st.force, st.extra):
                    if s is not None:
                        s.clear()
                self._reset_time()
            elif t_v[0] == last or (t_v[-1] <= last):
                self.faults["duplicate" if t_v[0] == last or np.any(t_v == last) else "out_of_order"] += 1
                return False
            else:
                self.faults["out_of_order"] += 1
                return False
        if unsorted is None:
            unsorted = bool(np.any(np.diff(t_v) <= 0))
        if unsorted:
            self.faults["unsorted_stamps"] += 1
            return False
        st.vib.append(t_v, vib, chunk.vibration_valid)
        t_d = np.asarray(chunk.deformation_t_ns, dtype=np.int64)
        if t_d.size:
            last_d = st.dfm.last_t_ns
            keep = None if last_d is None else t_d > last_d
            if keep is None or keep.all():  # the usual case: no copies
                st.dfm.append(t_d, dfm, chunk.deformation_valid)
                if extra is not None:
                    st.extra.append(t_d, extra)
            else:
                dv = None if chunk.deformation_valid is None else np.asarray(chunk.deformation_valid)[keep]
                st.dfm.append(t_d[keep], dfm[:, keep], dv)
                if extra is not None:
                    st.extra.append(t_d[keep], extra[:, keep])
        if chunk.deformation_tare is not None:
            st.tare = np.array(chunk.deformation_tare, dtype=np.float64)  # a copy: messages own their arrays
        t_f = np.asarray(chunk.force_t_ns, dtype=np.int64)
        if t_f.size:
            f = np.asarray(chunk.force_n, dtype=np.float64)
            last_f = st.force.last_t_ns
            keep = None if last_f is None else t_f > last_f
            if keep is None or keep.all():
                st.force.append(t_f, f[None, :])
            else:
                st.force.append(t_f[keep], f[None, keep])
            if self._exploration:  # onset and release only; fixed windows never read it
                self._update_last_force(st)
                if f.size and np.fmax.reduce(f) >= self.release_n:  # fmax: NaN never hides a touch
                    st.hot_until_ns = int(t_f[-1])
        self._advance(int(t_v[0]), int(t_v[-1]))
        return True

    def _advance(self, first_ns: int, end_ns: int) -> None:
        """Move the newest vibration stamp to ``end_ns``; a message starting more than
        :data:`WATERMARK_STALL_S` after it ends a stall of every cell (no cell sent anything in between)."""
        latest = self._latest_ns
        if latest is None:
            self._latest_ns = end_ns
            return
        if first_ns - latest > self._stall_ns:
            self._jump = (latest, first_ns)
        if end_ns > latest:
            self._latest_ns = end_ns

    def _new_cell(self, cell_id: int, dtype_s: np.dtype, dtype_v: np.dtype) -> _CellState:
        """The state of a cell's first chunk; its body part's buffers are made with the part's first cell.

        A body part's buffers hold every cell of the part (one row each) in
        the sample types of the first chunk that reached the part.
        """
        part, _ = self._index[cell_id]
        buffers = self._parts.get(part.name)
        if buffers is None:
            n_s, n_v = self._shapes[cell_id]
            rate = self.robot.cell_types[part.cell_type].force.rate_hz
            smooth_k = int(math.ceil(1.5 * self.smooth_ns * 1e-9 * rate)) + 2
            buffers = self._parts[part.name] = _Part([c.id for c in part.cells], n_s, n_v, dtype_s, dtype_v,
                                                     self._n_extra[cell_id], self.buffer_capacity(cell_id), smooth_k)
        st = self._cells[cell_id] = _CellState(buffers, buffers.row[cell_id])
        return st

    def _update_last_force(self, st: _CellState) -> None:
        """The cell's mean finite force over the last ``smooth_s`` (kept when none is finite)."""
        self._update_last_force_rows(st.part, np.array([st.row]))

    def _update_last_force_rows(self, part: _Part, rows: np.ndarray) -> None:
        """:meth:`_update_last_force` of several cells of a body part at once.

        Each cell's last ``smooth_k`` force samples (more than ``smooth_s``
        holds at the cell type's force rate) are looked at as one row of a
        2-D array; the mean of those within ``smooth_s`` of the newest that
        are finite (summed in sample order) becomes the cell's latest force.  A cell whose oldest
        looked-at sample is still within ``smooth_s`` (samples faster than
        the rate says) is looked at again with all its samples in it.
        """
        buf = part.force
        rows = rows[buf.has[rows]]
        if not rows.size:
            return
        k = part.smooth_k
        lo, hi, last = buf.lo[rows], buf.hi[rows], buf.last[rows]
        start = last - self.smooth_ns
        first = hi - k
        more = (first > lo) & (buf.t[rows, np.maximum(first, 0)] >= start)
        if more.any():  # rare: widen the look for every row to the longest such window
            r = rows[more]
            k = int(max(hi[more] - lo[more] - np.array([np.searchsorted(buf.t[x, buf.lo[x]:buf.hi[x]], st_, "left")
                                                         for x, st_ in zip(r.tolist(), start[more].tolist())])))
        t, v, inside = buf.tails(rows, k)
        inside &= (t >= start[:, None]) & (t <= last[:, None])
        fin = inside & np.isfinite(v)
        n = fin.sum(axis=1)
        total = np.cumsum(np.where(fin, v, 0.0), axis=1)[:, -1]  # in sample order, as the compiled intake sums
        upd = n > 0
        part.last_force[rows[upd]] = total[upd] / n[upd]

    def _reset_time(self) -> None:
        self._ahead = None
        self._head = None
        self._swept_ns = None
        self._swept_key = None
        self._resumed_ns = None
        self._next_start_ns = None
        self._onset_ns = None
        self._emitted_current = False
        self._latest_ns = None
        self._trimmed_ns = None
        self._jump = None

    # ----------------------------------------------------------------- output
    def poll(self) -> list[Window]:
        """Windows finished by the data received so far."""
        if self._latest_ns is None:
            return []
        out = self._poll_fixed() if self.mode == "fixed" else self._poll_exploration()
        self._trim()
        return out

    def closing_exploration(self) -> tuple[int, int, int] | None:
        """The window the open exploration is cut as if its release holds: ``(start_ns, end_ns, exploration_id)``.

        While every cell has stayed below the release threshold since
        ``end_ns`` and the release time (``release_s``) runs, the exploration
        can only end as ``[start_ns, end_ns)``, or go on if a cell touches
        again before ``end_ns + release_s``.  None otherwise: no open
        exploration, a cell still touching, a window already cut at
        ``max_duration_s``, one shorter than ``min_duration_s`` (it would be
        dropped), or fixed mode.
        """
        if self.mode != "exploration" or self._onset_ns is None or self._emitted_current \
                or self._released_since is None or self._released_since - self._onset_ns < self.min_ns:
            return None
        return self._onset_ns, self._released_since, self._exploration_id

    def cut_ahead(self) -> Window | None:
        """The window of :meth:`closing_exploration` (None without one), cut now from the samples buffered.

        The same cut :meth:`poll` makes when the release is decided.  When
        the release is decided on this span and no sample has reached the
        buffers inside it since, nor a new tare of one of its cells
        (:meth:`_held_since`), :meth:`poll` returns this very window instead
        of cutting it again; otherwise it cuts it again (which then differs
        from this one unless the new samples were all invalid or the tare
        the same; :func:`~.ahead.same_window` tells).  The faults the cut
        finds (gaps, invalid samples) are counted once, when the
        exploration closes.
        """
        key = self.closing_exploration()
        if key is None:
            return None
        counted = self.faults.copy()
        try:
            window = self._make_window(key[0], key[1], key[2], "exploration")
            self._ahead_cut_faults = self.faults - counted
        finally:
            self.faults.clear()
            self.faults.update(counted)
        self._ahead = window
        self._ahead_marks = {name: [b.added.copy() for b in part.buffers] for name, part in self._parts.items()}
        return window

    def cut_fixed_ahead(self) -> bool:
        """Copy the next fixed window's samples buffered so far, so that closing it copies only the rest.

        A fixed window ``[start, end)`` closes when every live cell has a
        vibration sample at or after ``end`` (:meth:`poll`); until then its
        samples before the watermark (the newest stamp every live cell has
        reached) are known and, the buffers being append-only, stay what they
        are.  Once the watermark is within :data:`CUT_AHEAD_S` of ``end``,
        this cuts ``[start, mark)``, the mark the last whole multiple of every
        stream's sample period from ``start`` not after the watermark (cells
        sampling at their own instants then hold as many samples before it;
        the whole window when the watermark passed ``end`` and the window
        waits for late cells, ``lateness_s``), as one set of stacks (the cut of
        :meth:`poll`, one copy per buffer and stream) and returns True; the
        poll that closes the window then cuts only ``[mark, end)``, copies
        those samples into the room left after the head and combines the
        widest steps of both parts, exactly (a gap is a step between
        consecutive samples, and the step across the mark is at least each
        part's step to or from the mark).  The window is the one a single cut
        makes, to the bit: the same arrays, dtypes, layouts, gaps and fault
        counts.  It falls back to the single cut whenever the head does not
        hold: a sample before the mark appended since, a new body part, a
        window that would not be one set of stacks, a clock jump (which drops
        the head), new window settings.
        Returns False when nothing was cut: not fixed mode, the window's end
        still further away, its head already cut, or the head not one set of
        stacks (then not tried again for this window).
        """
        kernel = fast.kernel_module() if COMPILED_CUT else None
        if self.mode != "fixed" or self._next_start_ns is None or self._latest_ns is None or kernel is None:
            return False
        start = self._next_start_ns
        end = start + self.length_ns
        if self._head is not None and self._head.window == (start, end):
            return False
        # the head is [start, mark): every live cell's newest sample in, the mark on the grid of whole sample
        # periods from the start (so that cells sampling at their own instants hold as many samples before it);
        # the whole window while it waits for late cells (``lateness_s``)
        newest = self._vibration_watermark() + 1
        mark = end if newest >= end else start + (newest - start) // self._head_step_ns * self._head_step_ns
        if mark <= start or end - mark > CUT_AHEAD_S * 1e9:
            return False
        counted = self.faults.copy()
        try:
            cuts = self._part_cuts(kernel, start, mark)
            order = self._stack_order(cuts) if all(c[-1] for c in cuts) else None
        finally:  # the faults the head shows are counted when the window closes, by the cut that closes it
            self.faults.clear()
            self.faults.update(counted)
        if order is None:  # not tried again for this window
            self._head = _Head((start, end), mark, None, (0, 0, 0), None, {})
            return False
        below = {name: _below(c, 1) for name, c in zip(self._parts, cuts)}
        # room after the head for the samples due before the end, each stream at its cell type's rate: the
        # window's arrays then take them as they are (else they are copied once more, into arrays that fit)
        ct = self.robot.cell_types[self.robot.body_part(self._part_names[0]).cell_type]
        p0, vc0, dc0, fc0 = order[0][:4]
        room = tuple(0 if mark == end else _due(int(buf.t[0, int(cut[1, 0]) - 1]), end, rate)
                     for buf, cut, rate in ((p0.vib, vc0, ct.vibration.rate_hz), (p0.dfm, dc0, ct.deformation.rate_hz),
                                            (p0.force, fc0, ct.force.rate_hz)))
        head = _Head((start, end), mark, None, tuple(int(c[1, 0] - c[0, 0]) for c in (vc0, dc0, fc0)),
                     np.concatenate([c[1][3] for c in order]), below)
        head.arrays = _stack_arrays(order, None, room)
        # the window's cells as views of those arrays' rows, made now: closing the window sets each one's gap and
        # tare (used only where the room fits, the arrays then being the window's)
        head.stacks = self._stack_cells(order, head.arrays, None)
        self._head = head
        return True

    def _finish_fixed(self, kernel, start: int, end: int) -> Window | None:
        """The fixed window ``[start, end)`` from the head :meth:`cut_fixed_ahead` cut and the samples since,
        or None where the head does not hold (:meth:`_make_window` cuts it whole then)."""
        head, self._head = self._head, None
        if head is None or head.arrays is None or head.window != (start, end) or kernel is None \
                or head.below.keys() != self._parts.keys():
            return None
        cuts = self._part_cuts(kernel, head.mark, end)
        # no sample before the mark came since: each row's samples ever appended before it are as many as then
        if any(not all(np.array_equal(a, b) for a, b in zip(_below(c, 0), head.below[name]))
               for name, c in zip(self._parts, cuts)):
            return None
        if (order := self._stack_order(cuts)) is None:
            return None
        vib_v, vib_t, dfm_v = head.arrays[:3]
        if head.mark == end:  # the whole window was cut ahead (it waited for late cells): nothing since
            widest = head.widest
        else:
            if not all(c[-1] for c in cuts) or (order[0][4] is None) != (head.arrays[5] is None) \
                    or (order[0][0].vib.v.dtype, order[0][0].dfm.v.dtype) != (vib_v.dtype, dfm_v.dtype):
                return None
            # the widest step over the whole window: each part's (its outer edge the mark), and the step across it
            later = np.concatenate([c[1][3] for c in order])
            first = np.concatenate([c[0].vib.t[np.arange(len(c[0].cell_ids)), c[1][0]] for c in order])
            widest = np.maximum(np.maximum(head.widest, later), first - vib_t[:, head.widths[0] - 1])
        made: dict[int, CellSignals] = {}
        w = Window(start, end, 0, "fixed")
        w.stacks = self._stack_parts(made, order, head, widest)
        for cid in self._cells:
            if (cell := made.get(cid)) is not None:
                w.cells[cid] = cell
        return w

    def flush(self) -> list[Window]:
        """End of stream: close an open exploration (if long enough)."""
        if self.mode == "exploration" and self._onset_ns is not None and not self._emitted_current \
                and self._latest_ns is not None:
            w = self._close_exploration(self._latest_ns + 1)
            return [w] if w else []
        return []

    def _poll_fixed(self) -> list[Window]:
        out = []
        if self._next_start_ns is None:
            firsts = [st.vib._t[st.vib._lo] for st in self._cells.values() if len(st.vib)]
            self._next_start_ns = first_fixed_start(int(min(firsts)), self.length_ns, self.hop_ns, self.grid_margin_ns)
        watermark = self._vibration_watermark()
        kernel = fast.kernel_module() if COMPILED_CUT and self._head is not None else None
        while self._next_start_ns + self.length_ns + self.lateness_ns <= watermark:
            start = self._next_start_ns
            w = None
            if self._head is not None:
                w = self._finish_fixed(kernel, start, start + self.length_ns)
                self.heads["used" if w is not None else "recut"] += 1
            if w is None:
                w = self._make_window(start, start + self.length_ns, 0, "fixed")
            if w.cells:
                out.append(w)
            else:  # inside a stall: no cell sent anything in it
                self.faults["windows_without_samples"] += 1
            self._next_start_ns += self.hop_ns
        return out

    def _vibration_watermark(self) -> int:
        """The latest vibration stamp every live cell has reached (fixed windows close on it).

        A cell more than :data:`WATERMARK_STALL_S` behind the most recent one
        (unplugged, dead) is not waited for.  Each body part's cells are
        looked at together, as one array of their newest stamps.
        """
        newest = self._latest_ns
        floor = self._stall_floor(newest)
        lasts = [int(live.min()) for p in self._parts.values()
                 if (live := (last := p.vib.last[p.vib.has])[last >= floor]).size]
        return min(lasts) if lasts else newest

    def _stall_floor(self, newest: int) -> int:
        """Cells whose data ends before this are not waited for: :data:`WATERMARK_STALL_S` behind the newest.

        After a stall of every cell (a driver stopped: a message starts more
        than that after the newest stamp held, :meth:`_advance`), the cells
        that were live before it are waited for until the newest stamp has
        moved on by that much again: the first body part's message after the
        stall must not make the others, whose messages follow, look dead.
        """
        floor = newest - self._stall_ns
        if self._jump is not None:
            before, after = self._jump
            if newest < after + self._stall_ns:
                floor = min(floor, before - self._stall_ns)
            else:
                self._jump = None
        return floor

    def _watermark(self) -> int | None:
        """The latest time every live cell has force data for (None before any force).

        Decisions made on data up to here do not depend on how the cells'
        messages interleaved or were batched.  A cell more than
        :data:`WATERMARK_STALL_S` behind the most recent one is not waited for.
        The live cells are kept as each body part's rows (``_live_rows``);
        every step looks at a part's cells together.
        """
        held = [(part, h) for part in self._parts.values() if (h := part.held_force()) is not None]
        if not held:
            self._live_rows = []
            return None
        floor = self._stall_floor(max(newest for _, (_, _, newest, _) in held))
        self._live_rows, lows = [], []
        for part, (rows, last, _, oldest) in held:
            if oldest >= floor:  # every held cell is live: the rows as held, the same array while they last
                self._live_rows.append((part, rows))
                lows.append(oldest)
            elif (keep := last >= floor).any():
                self._live_rows.append((part, rows[keep]))
                lows.append(int(last[keep].min()))
        return min(lows)

    @property
    def _live(self) -> list[_CellState]:
        """The live cells of the last :meth:`_watermark` (those not stalled behind the newest)."""
        return [self._cells[part.cell_ids[r]] for part, rows in self._live_rows for r in rows.tolist()]

    def _force_at(self, st: _CellState, t_ns: int) -> float:
        """The cell's mean finite force over the ``smooth_s`` up to ``t_ns`` (its latest when it ends there).

        The sum runs in sample order (a cumulative sum), so this equals
        :meth:`_forces_at`, which sums many cells' samples at once, to the bit.
        """
        fs = st.force
        last = fs.last_t_ns
        if last is None or last <= t_ns:
            return st.last_force_n
        t, lo = fs._t, fs._lo
        j = lo + int(t[lo:fs._hi].searchsorted(t_ns, side="right"))  # the samples up to t_ns
        i = lo + int(t[lo:j].searchsorted(t_ns - self.smooth_ns, side="left"))
        recent = fs._v[0, i:j]
        finite = recent[np.isfinite(recent)]
        if finite.size:
            return float(np.cumsum(finite)[-1] / finite.size)
        before = fs._v[0, lo:j]  # none finite in the last smooth_s: the last finite one
        finite = before[np.isfinite(before)]
        return float(finite[-1]) if finite.size else 0.0

    def _forces_at(self, part: _Part, rows: np.ndarray, t_ns: int) -> np.ndarray:
        """:meth:`_force_at` of a body part's cells (``rows``, each holding force samples) at ``t_ns`` at once.

        Each cell's newest samples (``smooth_k``, more than ``smooth_s`` holds
        at the force rate, plus :data:`FORCE_TAIL_EXTRA` for samples after
        ``t_ns``) are one row of a 2-D array; the finite ones inside the
        ``smooth_s`` up to ``t_ns`` are summed in order.  A cell whose look
        does not reach back far enough, or with no finite sample in it, goes
        through :meth:`_force_at` alone.
        """
        buf = part.force
        out = part.last_force[rows].copy()  # a cell whose newest sample is at or before t_ns: its latest
        later = buf.last[rows] > t_ns
        if not later.any():
            return out
        r = rows[later]
        t, v, inside = buf.tails(r, part.smooth_k + FORCE_TAIL_EXTRA)
        start = t_ns - self.smooth_ns
        short = inside[:, 0] & (t[:, 0] >= start)  # the look may miss older samples of the smooth_s
        fin = inside & (t >= start) & (t <= t_ns) & np.isfinite(v)
        n = fin.sum(axis=1)
        total = np.cumsum(np.where(fin, v, 0.0), axis=1)[:, -1]
        ok = (n > 0) & ~short
        got = np.empty(r.size)
        got[ok] = total[ok] / n[ok]
        for i in np.flatnonzero(~ok).tolist():  # rare: a long look, or nothing finite to average
            got[i] = self._force_at(self._cells[part.cell_ids[int(r[i])]], t_ns)
        out[later] = got
        return out

    def _contact_at(self, t_ns: int) -> tuple[bool, bool]:
        """(any cell at or above onset, all cells below release) at ``t_ns``."""
        # a stalled cell's last force is no contact
        peaks = [float(f.max()) for part, rows in self._live_rows if (f := self._forces_at(part, rows, t_ns)).size]
        if not peaks:
            return False, True
        return max(peaks) >= self.onset_n, max(peaks) < self.release_n

    def _poll_exploration(self) -> list[Window]:
        """Run the exploration state machine up to the watermark, stopping at every moment it could change.

        Between the previous poll's watermark and this one the machine is
        stepped at each time where onset, release, re-contact, the end of the
        release time or the longest duration falls (found on the smoothed
        force of the cells that touched), then at the watermark: the windows
        are those of a poll after every sample, whatever the batches were.
        """
        out: list[Window] = []
        now = self._watermark()
        if now is None:
            return out
        # The watermark moves with the slowest body part's messages, so most polls find it where the last
        # left it: with the same live cells and settings, the forces up to it and so the step are the same.
        key = (now, self.onset_n, self.release_n, self.release_ns, self.min_ns, self.max_ns)
        if key == self._swept_key and len(self._live_rows) == len(self._swept_rows) and all(
                p is q and (a is b or np.array_equal(a, b))
                for (p, a), (q, b) in zip(self._live_rows, self._swept_rows)):
            return out
        self._swept_key, self._swept_rows = key, self._live_rows
        if self._swept_ns is None:  # from the first force sample held
            t = min(int(st.force._t[st.force._lo]) for st in self._cells.values() if len(st.force)) - 1
        else:
            t = min(self._swept_ns, now)
        stalls = self._stalls(t, now) if now - t > self._stall_ns else []
        for a, b in stalls + [(now, None)]:
            while True:
                nxt = self._next_event(t, a)
                if nxt is None:
                    break
                out += self._step(nxt)
                t = nxt
            out += self._step(a)
            t = a
            if b is not None:  # no cell sent anything from a to b: a gap, never part of an exploration
                self.faults["stall"] += 1
                if self._onset_ns is not None and not self._emitted_current:
                    w = self._close_exploration(a + 1)
                    if w:
                        out.append(w)
                self._onset_ns = None
                self._emitted_current = False
                self._released_since = None
                self._resumed_ns = b
                t = b - 1
        self._swept_ns = now
        return out

    def _stalls(self, after_ns: int, until_ns: int) -> list[tuple[int, int]]:
        """Spans ``(a, b)`` in ``(after_ns, until_ns]`` longer than :data:`WATERMARK_STALL_S` with no force sample
        of any cell: ``a`` the last sample before, ``b`` the first after (a driver stopped, a bus gone).

        Looked for only when the watermark moved by more than that since the
        previous poll, so it costs one pass over the samples of such a poll.
        """
        stamps = [st.force.between(after_ns, until_ns + 1)[0] for st in self._cells.values() if len(st.force)]
        t = np.unique(np.concatenate(stamps)) if stamps else np.zeros(0, np.int64)
        if t.size < 2:
            return []
        gap = np.flatnonzero(np.diff(t) > self._stall_ns)
        return [(int(t[i]), int(t[i + 1])) for i in gap.tolist()]

    def _next_event(self, after_ns: int, until_ns: int) -> int | None:
        """The first time in ``(after_ns, until_ns)`` where a step could change the state (None: none before).

        Only cells with a force at or above release since ``after_ns - smooth_s``
        can move the smoothed force across a threshold; while one of them
        stays above release on every raw sample, no release can happen, so a
        long touch costs one check of its strongest cell per poll.
        """
        if after_ns >= until_ns:
            return None
        since = after_ns - self.smooth_ns
        hot = [self._cells[part.cell_ids[r]] for part, rows in self._live_rows
               for r in rows[part.hot[rows] & (part.hot_until[rows] >= since)].tolist()]
        candidates = []
        if self._onset_ns is None:  # idle: an onset needs a cell whose raw force reached onset
            level_cells = [st for st in hot if self._raw(st, since, until_ns, np.fmax) >= self.onset_n]
            first = self._first_crossing(level_cells, after_ns, until_ns, lambda c: c >= self.onset_n)
            if first is not None:
                candidates.append(first)
        else:
            if not self._emitted_current:
                candidates.append(self._onset_ns + self.max_ns)
            if self._released_since is None:  # open: a release needs every cell below release
                if not hot:
                    if self._probed_onset != self._onset_ns:  # once per exploration, never a step per nanosecond
                        self._probed_onset = self._onset_ns
                        candidates.append(after_ns + 1)  # nobody touches: released from here on
                else:
                    strongest = max(hot, key=lambda st: st.last_force_n)
                    if not self._raw(strongest, since, until_ns, np.minimum) >= self.release_n:  # NaN: look closer
                        first = self._first_crossing(hot, after_ns, until_ns, lambda c: c < self.release_n)
                        if first is not None:
                            candidates.append(first)
            else:  # released: a new contact needs a cell at or above release, else the release time ends
                level_cells = [st for st in hot if self._raw(st, since, until_ns, np.fmax) >= self.release_n]
                first = self._first_crossing(level_cells, after_ns, until_ns, lambda c: c >= self.release_n)
                if first is not None:
                    candidates.append(first)
                candidates.append(self._released_since + self.release_ns)
        candidates = [c for c in candidates if after_ns < c < until_ns]
        return min(candidates) if candidates else None

    @staticmethod
    def _raw(st: _CellState, start_ns: int, end_ns: int, reduce) -> float:
        """``reduce`` (np.fmax, np.minimum) of the cell's raw force samples in ``[start_ns, end_ns]`` (NaN if none)."""
        _, f, _ = st.force.between(start_ns, end_ns + 1)
        return float(reduce.reduce(f[0])) if f.shape[1] else math.nan

    def _first_crossing(self, cells: list[_CellState], after_ns: int, until_ns: int, test) -> int | None:
        """The first force stamp of ``cells`` in ``(after_ns, until_ns)`` where the highest smoothed force passes ``test``."""
        if not cells:
            return None
        grid = np.unique(np.concatenate([st.force.between(after_ns + 1, until_ns)[0] for st in cells]))
        if not grid.size:
            return None
        level = np.max([self._smoothed_at(st, grid) for st in cells], axis=0)
        hit = np.flatnonzero(test(level))
        return int(grid[hit[0]]) if hit.size else None

    def _smoothed_at(self, st: _CellState, times_ns: np.ndarray) -> np.ndarray:
        """:meth:`_force_at` at many times at once (mean of the finite force samples in the ``smooth_s`` up to each)."""
        t, f, _ = st.force.between(int(times_ns[0]) - self.smooth_ns, int(times_ns[-1]) + 1)
        v = f[0]
        ok = np.isfinite(v)
        csum = np.concatenate(([0.0], np.cumsum(np.where(ok, v, 0.0))))
        count = np.concatenate(([0], np.cumsum(ok)))
        i = np.searchsorted(t, times_ns - self.smooth_ns, side="left")
        j = np.searchsorted(t, times_ns, side="right")
        n = count[j] - count[i]
        mean = (csum[j] - csum[i]) / np.maximum(n, 1)
        if np.all(n > 0):
            return mean
        # none finite in the smooth_s up to a time: the last finite sample before it (0 without one), and
        # at or after the cell's newest sample its latest mean -- as _force_at, for all such times at once
        fs = st.force
        lo, hi = fs._lo, fs._hi
        ft, fv = fs._t[lo:hi], fs._v[0, lo:hi]
        ok = np.isfinite(fv)
        fin_t, fin_v = ft[ok], fv[ok]
        k = np.searchsorted(fin_t, times_ns, side="right") - 1
        held = np.where(k >= 0, fin_v[np.maximum(k, 0)] if fin_v.size else 0.0, 0.0)
        last = fs.last_t_ns
        held = np.where(np.int64(last if last is not None else np.iinfo(np.int64).max) <= times_ns,
                        st.last_force_n, held)
        return np.where(n > 0, mean, held)

    def _step(self, now: int) -> list[Window]:
        """One step of the exploration state machine at ``now`` (at or before the watermark)."""
        out: list[Window] = []
        self._now_ns = now
        touching, released = self._contact_at(now)
        if self._onset_ns is None:
            if touching:
                self._onset_ns = self._onset_time()
                self._exploration_id += 1
                self._emitted_current = False
                self._released_since = None
            return out
        if not self._emitted_current and now - self._onset_ns >= self.max_ns:
            w = self._close_exploration(self._onset_ns + self.max_ns)
            self._emitted_current = True
            if w:
                out.append(w)
        if released:
            if self._released_since is None:
                self._released_since = self._release_time()
            if now - self._released_since >= self.release_ns:
                if not self._emitted_current:
                    w = self._close_exploration(self._released_since)
                    if w:
                        out.append(w)
                self._onset_ns = None
                self._emitted_current = False
        else:
            self._released_since = None
        return out

    def _smoothed_force(self, st: _CellState, start_ns: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Force stamps since ``start_ns``, the mean force over the ``smooth_s`` before each, and the raw force."""
        t, f, _ = st.force.between(start_ns - self.smooth_ns, self._now_ns + 1)
        f = np.where(np.isfinite(f[0]), f[0], 0.0)
        csum = np.concatenate(([0.0], np.cumsum(f)))
        first = np.searchsorted(t, t - self.smooth_ns, side="right")
        last = np.arange(1, t.size + 1)
        mean = (csum[last] - csum[first]) / np.maximum(last - first, 1)
        keep = t >= start_ns
        return t[keep], mean[keep], f[keep]

    def _onset_time(self) -> int:
        """Start of the current run of smoothed force at or above onset, over cells touching now."""
        best = self._now_ns
        for st in self._live:
            if self._force_at(st, self._now_ns) < self.onset_n:
                continue  # an older touch of a cell that has since let go is not this onset
            t, f, raw = self._smoothed_force(st, self._now_ns - self._retain_ns)
            below = np.nonzero(f < self.onset_n)[0]
            run_start = below[-1] + 1 if below.size else 0
            if run_start >= t.size:
                continue
            # The smoothed force lags by up to smooth_s: the onset is the first
            # raw sample of the run at or above the threshold within that lag.
            lag_start = int(np.searchsorted(t, t[run_start] - self.smooth_ns, side="left"))
            raw_below = np.nonzero(raw[lag_start:run_start + 1] < self.onset_n)[0]
            onset = lag_start + raw_below[-1] + 1 if raw_below.size else lag_start
            best = min(best, int(t[min(onset, run_start)]))
        if self._resumed_ns is not None:  # a touch held through a stall starts after it, never before
            best = max(best, self._resumed_ns)
        return best

    def _release_time(self) -> int:
        """First stamp after which every cell's smoothed force stayed below release."""
        best = self._onset_ns
        for st in self._live:
            t, f, raw = self._smoothed_force(st, self._onset_ns)
            above = np.nonzero(f >= self.release_n)[0]
            if not above.size:
                continue
            # The smoothed force lags by up to smooth_s: the release is the
            # stamp after the last raw sample above the threshold before it.
            k = above[-1]
            raw_above = np.nonzero(raw[: k + 1] >= self.release_n)[0]
            r = raw_above[-1] if raw_above.size else k
            best = max(best, int(t[min(r + 1, t.size - 1)]))
        return best

    def _close_exploration(self, end_ns: int) -> Window | None:
        start = self._onset_ns
        ahead, self._ahead = self._ahead, None
        if end_ns - start < self.min_ns:
            self.faults["exploration_too_short"] += 1
            return None
        if ahead is not None and (ahead.start_ns, ahead.end_ns, ahead.exploration_id) == \
                (start, end_ns, self._exploration_id) and self._held_since(ahead):
            self.faults.update(self._ahead_cut_faults)  # what its cut found, counted as the cut it saves would
            return ahead
        return self._make_window(start, end_ns, self._exploration_id, "exploration")

    def _held_since(self, window: Window) -> bool:
        """Whether cutting ``window`` (cut by :meth:`cut_ahead`) again would copy the same samples: no sample
        appended to any buffer since lies inside its span, no body part's buffers are new, and each of its
        cells has the tare it had.  The buffers are append-only between a clock jump's reset (which abandons
        the exploration, :meth:`_reset_time`), and an open exploration's samples are never trimmed."""
        marks = self._ahead_marks
        if marks.keys() != self._parts.keys():
            return False
        for name, part in self._parts.items():
            for buf, before in zip(part.buffers, marks[name]):
                if buf.added_inside(before, window.start_ns, window.end_ns):
                    return False
        return all(_same_tare(cell.deformation_tare, self._cells[cid].tare) for cid, cell in window.cells.items())

    def _make_window(self, start: int, end: int, exploration_id: int, mode: str) -> Window:
        """The window ``[start, end)``: every cell's samples in it, as :class:`CellSignals` (copies).

        Each body part's buffers are cut at once by the compiled backend
        (:func:`.numba_kernel.cut_rows`: where each row's samples lie, how
        many are invalid, the widest step), so a cell costs a few slice
        copies; a cell with invalid samples, or every cell without the
        compiled backend (or with :data:`COMPILED_CUT` off), takes the
        per-cell path (:meth:`_cell_window`), which gives the same arrays.
        """
        w = Window(start, end, exploration_id, mode)
        kernel = fast.kernel_module() if COMPILED_CUT else None
        if kernel is None:
            for cid, st in self._cells.items():
                if (cell := self._cell_window(cid, st, start, end)) is not None:
                    w.cells[cid] = cell
            return w
        made: dict[int, CellSignals] = {}
        cuts = self._part_cuts(kernel, start, end)
        if all(c[-1] for c in cuts) and (order := self._stack_order(cuts)) is not None:
            w.stacks = self._stack_parts(made, order)
        else:
            for part, vc, dc, fc, xc, held, clean, aligned in cuts:
                if aligned:  # every cell clean, its window at the same positions as the others' (the common case)
                    self._stack_parts(made, [(part, vc, dc, fc, xc)])
                else:
                    self._cut_part(made, part, start, end, vc, dc, fc, xc, held, clean)
        for cid in self._cells:  # the cells in the order they first sent, as the per-cell path gives them
            if (cell := made.get(cid)) is not None:
                w.cells[cid] = cell
        return w

    def _part_cuts(self, kernel, start: int, end: int) -> list[tuple]:
        """Each body part's buffers cut at ``[start, end)`` (:meth:`_RowBuffer.cut`): ``(part, vc, dc, fc, xc,
        held, clean, aligned)``, the rows holding vibration samples, those without invalid ones, and whether
        every row is clean and holds as many samples as the others (:func:`_aligned`)."""
        cuts = []
        for part in self._parts.values():
            # the widest step of the vibration samples (gaps), the invalid deformation samples, positions else
            vc, dc, fc = part.vib.cut(kernel, start, end), part.dfm.cut(kernel, start, end, 1), \
                part.force.cut(kernel, start, end, 0)
            xc = part.extra.cut(kernel, start, end, 0) if part.extra is not None else None
            held = vc[1] > vc[0]
            clean = held & (vc[2] == 0) & (dc[2] == 0)
            cuts.append((part, vc, dc, fc, xc, held, clean,
                         bool(clean.all()) and _aligned(vc, dc, fc, xc)))
        return cuts

    def _stack_order(self, cuts: list) -> list | None:
        """The cuts of :meth:`_make_window` in the robot's order of body parts when the window can be one set of
        stacks: every body part of the robot in it, of one cell type, and every cell with as many samples of
        each stream as the others; else None."""
        if len(cuts) != len(self.robot.body_parts) or len({p.cell_type for p in self.robot.body_parts}) != 1:
            return None
        by_name = dict(zip(self._parts, cuts))  # the body parts' names, in the order of ``cuts``
        order = [by_name.get(name) for name in self._part_names]
        if any(c is None for c in order):
            return None
        first = order[0]
        widths = [int(x[1, 0] - x[0, 0]) if x is not None else None for x in first[1:5]]
        dtypes = (first[0].vib.v.dtype, first[0].dfm.v.dtype)
        for c in order[1:]:
            if (c[0].vib.v.dtype, c[0].dfm.v.dtype) != dtypes or (c[4] is None) != (first[4] is None) \
                    or [int(x[1, 0] - x[0, 0]) if x is not None else None for x in c[1:5]] != widths:
                return None
        return order

    def _stack_parts(self, made: dict[int, CellSignals], order: list, head: _Head | None = None,
                     widest: np.ndarray | None = None) -> CellStacks:
        """The body parts of ``order`` (:meth:`_make_window`'s cuts, each part's cells clean and with as many
        samples of each buffer as the others, :func:`_aligned`; several parts: :meth:`_stack_order`) copied into
        one set of arrays, one copy per buffer and stream instead of one per cell (:func:`_rows`), each cell's
        arrays views of its row; the same values, dtypes and C-contiguous layouts as the cell-by-cell copies.
        Returns the :class:`~.aggregation.CellStacks` of those arrays.

        ``head``: the window's earlier samples, cut before (:meth:`cut_fixed_ahead`); the cuts are then of the
        rest of the window, copied after them (into the head's own arrays when their room fits), and
        ``widest`` gives each row's widest step over the whole window (its gap)."""
        arrays = _stack_arrays(order, head)
        gaps: list[bool] = []
        r0 = 0
        for part, vc, *_ in order:
            r1 = r0 + len(part.cell_ids)
            gaps += ((vc[3] if widest is None else widest[r0:r1]) > self._gap_limit_ns(part.cell_ids[0])).tolist()
            r0 = r1
        if n_gaps := sum(gaps):
            self.faults["gap"] += n_gaps
        ids = [cid for c in order for cid in c[0].cell_ids]
        if head is not None and arrays is head.arrays:  # the cells made with the head: their gap and tare now
            for cell, cid, gap in zip(head.stacks.cells, ids, gaps):
                cell.gap = gap
                cell.deformation_tare = self._cells[cid].tare
                made[cid] = cell
            return head.stacks
        stacks = self._stack_cells(order, arrays, gaps)
        made.update(zip(ids, stacks.cells))
        return stacks

    def _stack_cells(self, order: list, arrays: tuple, gaps: list[bool] | None) -> CellStacks:
        """The :class:`~.aggregation.CellStacks` of :func:`_stack_arrays`' ``arrays`` for ``order``'s cells: each
        cell's arrays the views of its row, with its tare and ``gaps`` (False where None)."""
        vib_v, vib_t, dfm_v, dfm_t, force, extra = arrays
        ids = [cid for c in order for cid in c[0].cell_ids]
        cells = tuple(CellSignals(vib_v[r], vib_t[r], dfm_v[r], dfm_t[r], force[r], True,
                                  bool(gaps[r]) if gaps is not None else False, 0,
                                  extra[r] if extra is not None else None, self._cells[cid].tare)
                      for r, cid in enumerate(ids))
        return CellStacks(cells, *arrays)

    def _cut_part(self, made: dict[int, CellSignals], part: _Part, start: int, end: int, vc: np.ndarray,
                  dc: np.ndarray, fc: np.ndarray, xc: np.ndarray | None, held: np.ndarray, clean: np.ndarray) -> None:
        """One body part's cells of the window, cell by cell, from its buffers' cuts (``vc``, ``dc``, ``fc``,
        ``xc``: :meth:`_RowBuffer.cut`); a cell with invalid samples takes :meth:`_cell_window`."""
        (v0, v1, _, v_step), (d0, d1) = vc.tolist(), dc[:2].tolist()
        f0, f1 = fc[:2].tolist()
        x0, x1 = xc[:2].tolist() if xc is not None else (None, None)
        limit = self._gap_limit_ns(part.cell_ids[0])
        vib, dfm = part.vib, part.dfm
        clean_l = clean.tolist()
        for r in np.flatnonzero(held).tolist():
            cid = part.cell_ids[r]
            st = self._cells[cid]
            if not clean_l[r]:  # invalid samples: removed on the per-cell path
                if (cell := self._cell_window(cid, st, start, end)) is not None:
                    made[cid] = cell
                continue
            i, j, a, b = v0[r], v1[r], d0[r], d1[r]
            gap = v_step[r] > limit
            if gap:
                self.faults["gap"] += 1
            x = part.extra.v[:, r, x0[r]:x1[r]].copy() if x0 is not None else None
            made[cid] = CellSignals(vib.v[:, r, i:j].copy(), vib.t[r, i:j].copy(), dfm.v[:, r, a:b].copy(),
                                    dfm.t[r, a:b].copy(), part.force.v[0, r, f0[r]:f1[r]].copy(), True, gap, 0,
                                    x, st.tare)

    def _cell_window(self, cid: int, st: _CellState, start: int, end: int) -> CellSignals | None:
        """One cell's samples in ``[start, end)``, invalid ones removed; None if it has no valid vibration sample."""
        tv, v, okv = st.vib.between(start, end)
        if tv.size == 0:
            return None
        # Only samples inside the window: a V sample from before it would
        # enter V's Hjorth parameters (S samples before the first V sample
        # of the window are simply not paired, at most one V period).
        td, d, okd = st.dfm.between(start, end)
        x = st.extra.between(start, end)[1] if st.extra is not None else None
        tf, f, _ = st.force.between(start, end)
        n_bad = int(np.count_nonzero(~okv) + np.count_nonzero(~okd))
        valid = n_bad <= self.max_invalid_fraction * (okv.size + okd.size)
        if n_bad:
            # Invalid samples are removed, never replaced: the time stamps stay
            # true, so the hold of V and the derivative see a short hole.
            self.faults["windows_with_invalid_samples"] += 1
            tv, v, td, d = tv[okv], v[:, okv], td[okd], d[:, okd]
            x = x[:, okd] if x is not None else None
            if tv.size == 0:
                return None
        gap = self._has_gap(cid, tv, start, end)
        if gap:
            self.faults["gap"] += 1
        return CellSignals(v, tv, d, td, f[0], valid, gap, n_bad, x, st.tare)

    def _gap_limit_ns(self, cell_id: int) -> float:
        """The longest step between a cell's vibration samples that is not a gap: :data:`GAP_PERIODS` periods."""
        part, _ = self._index[cell_id]
        return GAP_PERIODS * 1e9 / self.robot.cell_types[part.cell_type].vibration.rate_hz

    def _has_gap(self, cell_id: int, t_ns: np.ndarray, start: int, end: int) -> bool:
        """A hole of more than :data:`GAP_PERIODS` vibration periods inside the window."""
        limit = self._gap_limit_ns(cell_id)
        edges = np.concatenate(([start], t_ns, [end]))
        return bool(np.max(np.diff(edges)) > limit)

    def _trim(self) -> None:
        horizon = self._latest_ns - self._retain_ns
        if self.mode == "fixed" and self._next_start_ns is not None:
            horizon = min(horizon, self._next_start_ns)
        if self.mode == "exploration" and self._onset_ns is not None and not self._emitted_current:
            # The open exploration's samples are kept until its window is cut.  Once it
            # was cut at max_duration_s only the release is still awaited, which needs
            # no more than the retained time: a contact held for minutes (an object
            # carried, a cell that never lets go) must not keep every sample since
            # its onset (memory and the release scan would grow without bound).
            horizon = min(horizon, self._onset_ns)
        if self._trimmed_ns is not None and self._trimmed_ns <= horizon < self._trimmed_ns + TRIM_STEP_NS:
            return  # samples are dropped once per TRIM_STEP_NS of horizon, not at every poll
        self._trimmed_ns = horizon
        for part in self._parts.values():
            for buf in part.buffers:
                buf.trim_before(horizon)

    def buffer_capacity(self, cell_id: int) -> tuple[int, int, int]:
        """Samples of a cell's vibration, deformation and force buffers, sized from its cell type's rates.

        ``BUFFER_HEADROOM`` times (the longest span kept, :data:`BUFFER_SLACK_S`
        included) times the rate: the buffers never grow unless :meth:`retune`
        makes the kept span longer.
        """
        part, _ = self._index[cell_id]
        ct = self.robot.cell_types[part.cell_type]
        span_s = self._retain_ns / 1e9 + BUFFER_SLACK_S
        return tuple(int(math.ceil(BUFFER_HEADROOM * span_s * rate))
                     for rate in (ct.vibration.rate_hz, ct.deformation.rate_hz, ct.force.rate_hz))

    @property
    def buffer_bytes(self) -> int:
        """Bytes of every cell's sample buffers (what the windower holds, kept samples and headroom)."""
        return sum(b.nbytes for p in self._parts.values() for b in p.buffers)

    @property
    def exploration_id(self) -> int:
        """Id of the current (or last) exploration; 0 before the first."""
        return self._exploration_id

    @property
    def in_contact(self) -> bool:
        """True while an exploration is open."""
        return self._onset_ns is not None


#: The dtypes :meth:`_RowBuffer.append_runs` hands to the compiled intake (:func:`.numba_kernel.append_runs`):
#: those the window node's buffers hold, compiled at set-up (:func:`.fast.warm_up`).  Other dtypes, arrays that
#: are not C-contiguous or are read-only (each would be another compiled variant, compiled while the node runs)
#: take the numpy path, which makes the same copies.
INTAKE_DTYPES = (np.dtype(np.int32), np.dtype(np.int64), np.dtype(np.float64))
_INTAKE_DTYPES = frozenset(INTAKE_DTYPES)
_INDEX_DTYPE = np.dtype(np.int64)
_NO_VALID = np.ones(1, dtype=bool)
#: The extra channels' values where a body part has none (:meth:`Windower._add_fused`; never written).
_NO_EXTRA = np.zeros((0, 0))
#: :meth:`Windower._add_fused` (:func:`.numba_kernel.add_part_runs`): the message written; to go run by run
#: (:meth:`Windower.add_many`); a row out of room.
_WRITTEN, _RUN_BY_RUN, _NO_ROOM = 0, 1, 2
#: The sample types the fused intake is compiled for (``make setup``): the skin cells' counts as the window
#: node converts them.  Others take the intake pass by pass, whose variants are compiled as well.
_FUSED_DTYPES = frozenset({np.dtype(np.int32)})
#: Whether the windower may use the compiled intake when the compiled backend is loaded (the tests switch it
#: off to compare both paths).
COMPILED_INTAKE = True
#: Whether the windower cuts its windows with the compiled backend when it is loaded (the tests switch it off to
#: compare both paths).
COMPILED_CUT = True


def rehearsal_window(robot: RobotDescription, length_s: float, vibration_dtype: np.dtype,
                     deformation_dtype: np.dtype, *, seed: int = 0) -> Window:
    """A window of every cell of ``robot``, all in contact, cut from seeded noise as the live path cuts one.

    One :class:`PartChunk` per body part of ``2 * length_s + 0.5`` s of
    samples at the cell types' rates (each cell on its own clock, a
    microsecond after the one before, as a driver stamps them) goes through
    :meth:`Windower.add_part` of a fixed-mode :class:`Windower` with hop
    ``length_s``; the first window it cuts is returned, its cells one set of
    stacks where the robot allows it (:class:`Window`).

    The window node describes it once, on the thread that describes, before
    its first window: the first description in a process allocates and pages
    in its buffers, plans its transforms and loads the compiled code for the
    data's sample types.  Without it the NAO's first window took 33-62 ms to
    describe instead of 10.

    Parameters
    ----------
    robot : RobotDescription
    length_s : float
        Window length [s].
    vibration_dtype, deformation_dtype : numpy dtype
        The sample types of the live data (those of its first chunk).
    seed : int
        Seed of the noise.

    Returns
    -------
    Window

    Raises
    ------
    ConfigError
        For a length the windower refuses.
    """
    # buffers for this window only (their size follows the longest exploration otherwise)
    windower = Windower(robot, mode="fixed", length_s=length_s, hop_s=length_s, lateness_s=0.0,
                        min_duration_s=0.0, max_duration_s=length_s)
    rng = np.random.default_rng(seed)
    span_ns = 2 * windower.length_ns + 500_000_000
    t0_ns = 1_000_000_000  # whole seconds: the grid of windows starts at the first hop after it
    force_n = max(1.0, 2.0 * windower.onset_n)
    k = 0
    for part in robot.body_parts:
        ct = robot.cell_types[part.cell_type]
        n = len(part.cells)
        stamps = []
        for rate_hz in (ct.vibration.rate_hz, ct.deformation.rate_hz):
            period_ns = 1e9 / rate_hz
            count = int(span_ns // period_ns)
            grid = t0_ns + np.round(np.arange(count) * period_ns).astype(np.int64)
            stamps.append((count, np.concatenate([grid + 1_000 * (k + i) for i in range(n)])))
        (n_a, t_a), (n_d, t_d) = stamps
        k += n
        chunk = PartChunk(
            np.array([c.id for c in part.cells], np.int64), np.full(n, n_a, np.int64), np.full(n, n_d, np.int64),
            rng.integers(100, 900, (len(ct.vibration.channels), n * n_a)).astype(vibration_dtype), t_a,
            rng.integers(100, 900, (len(ct.deformation.channels), n * n_d)).astype(deformation_dtype), t_d,
            force_n + rng.uniform(0.0, 0.1, n * n_d),
            extra=rng.uniform(0.0, 1.0, (len(ct.extra_channels), n * n_d)) if ct.extra_channels else None)
        windower.add_part(chunk)
    return windower.poll()[0]


@dataclass
class _Head:
    """The samples of the fixed window ``window`` before ``mark`` (:meth:`Windower.cut_fixed_ahead`).

    ``arrays``: their stacks (as :class:`~.aggregation.CellStacks`' arrays; None: not one set of stacks), each
    stream's first ``widths`` samples (vibration, deformation, force; the extra channels as deformation), with
    room after them for the samples due before the window's end; ``widest``: each row's widest step up to the
    mark; ``below``: per body part and buffer, each row's samples appended before the mark (:func:`_below`);
    ``stacks``: the window's cells as views of ``arrays``' rows, their gap and tare set when it closes."""

    window: tuple[int, int]
    mark: int
    arrays: tuple | None
    widths: tuple[int, int, int]
    widest: np.ndarray | None
    below: dict[str, list[np.ndarray]]
    stacks: CellStacks | None = None


def _below(cut: tuple, at: int) -> list[np.ndarray]:
    """For a body part's cut (:meth:`Windower._part_cuts`) whose row ``at`` of each buffer's positions is the first
    sample at or after a mark, each buffer's rows' samples ever appended before the mark: the samples appended
    (``added``) less those held from the mark on (never trimmed while the window they are in is open).  Rows
    hold their samples in time order, so the count grows only when a sample before the mark arrives."""
    part, vc, dc, fc, xc = cut[:5]
    return [buf.added - (buf.hi - c[at]) for buf, c in ((part.vib, vc), (part.dfm, dc), (part.force, fc), (part.extra, xc))
            if c is not None]


def _common_period_ns(robot: RobotDescription) -> int:
    """The least common multiple of every stream's sample period [ns] (a NAO skin cell: 1 ms and 4 ms give
    4 ms): between two of its multiples, a stream sampled regularly has as many samples whatever its phase.
    1 ns where a period is not a whole number of nanoseconds (the BioTac's 2.2 kHz)."""
    step = 1
    for ct in robot.cell_types.values():
        for rate in (ct.vibration.rate_hz, ct.deformation.rate_hz, ct.force.rate_hz):
            period = 1e9 / rate
            if abs(period - round(period)) > 1e-6:
                return 1
            step = math.lcm(step, int(round(period)))
    return step


def _due(last_ns: int, end_ns: int, rate_hz: float) -> int:
    """Samples due after ``last_ns`` and before ``end_ns`` at ``rate_hz``."""
    return max(0, math.ceil((end_ns - last_ns) * rate_hz / 1e9) - 1)


def _stack_arrays(order: list, head: _Head | None = None, room: tuple[int, int, int] = (0, 0, 0)) -> tuple:
    """The arrays of :meth:`Windower._stack_parts`: ``(vibration, vibration_t_ns, deformation, deformation_t_ns,
    force_n, extra)`` of ``order``'s cells, each stream's samples after ``head``'s (and ``room`` samples more,
    left unwritten)."""
    p0, vc0, dc0, fc0, xc0 = order[0][:5]
    n = sum(len(c[0].cell_ids) for c in order)
    nv, nd, nf = (int(x[1, 0] - x[0, 0]) for x in (vc0, dc0, fc0))
    hv, hd, hf = (0, 0, 0) if head is None else head.widths
    if head is not None and head.arrays[1].shape[1] == hv + nv and head.arrays[3].shape[1] == hd + nd \
            and head.arrays[4].shape[1] == hf + nf:
        arrays = head.arrays  # the room left fits the samples that came: written in place
    else:
        gv, gd, gf = hv + nv + room[0], hd + nd + room[1], hf + nf + room[2]
        arrays = (np.empty((n, p0.vib.n_channels, gv), p0.vib.v.dtype), np.empty((n, gv), np.int64),
                  np.empty((n, p0.dfm.n_channels, gd), p0.dfm.v.dtype), np.empty((n, gd), np.int64),
                  np.empty((n, gf), np.float64),
                  np.empty((n, p0.extra.n_channels, gd), np.float64) if xc0 is not None else None)
        if head is not None:  # copied once more: the head's room did not fit
            for out, early, k in zip(arrays, head.arrays, (hv, hv, hd, hd, hf, hd)):
                if out is not None:
                    out[..., :k] = early[..., :k]
    vib_v, vib_t, dfm_v, dfm_t, force, extra = arrays
    r0 = 0
    for part, vc, dc, fc, xc, *_ in order:
        r1 = r0 + len(part.cell_ids)
        for buf, cut, t_out, v_out, k, w in ((part.vib, vc, vib_t, vib_v, hv, nv), (part.dfm, dc, dfm_t, dfm_v, hd, nd)):
            _rows(t_out[r0:r1, k:k + w], buf.t, cut[0], w)
            _rows(v_out[r0:r1, :, k:k + w], buf.v, cut[0], w)
        _rows(force[r0:r1, hf:hf + nf], part.force.v[0], fc[0], nf)
        if extra is not None:
            _rows(extra[r0:r1, :, hd:hd + nd], part.extra.v, xc[0], nd)
        r0 = r1
    return arrays


def _same_tare(a: np.ndarray | None, b: np.ndarray | None) -> bool:
    """Whether two tares (arrays, or None) are the same bits: each message carries a fresh copy."""
    if a is None or b is None:
        return a is b
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


def _aligned(*cuts: np.ndarray | None) -> bool:
    """Whether every row of each :meth:`_RowBuffer.cut` (None: no such buffer) holds as many of its samples in the
    window as the others: rows filled in step, as a body part's messages fill them, at the same positions or,
    for cells sampling at their own instants (a clock per cell), one sample apart where the window's edges
    fall between two cells' samples."""
    for c in cuts:
        if c is not None and c.shape[1] and not ((w := c[1] - c[0]) == w[0]).all():
            return False
    return True


def _rows(dst: np.ndarray, src: np.ndarray, first: np.ndarray, width: int) -> None:
    """``dst[r, ..., :width] = src[..., r, first[r]:first[r] + width]`` for every row ``r`` of a
    :class:`_RowBuffer` array (``t``: rows x capacity, ``v``: channels x rows x capacity): one slice copy per
    distinct start, the rows starting there at once (one copy when the rows are filled in step; two or three
    for cells sampling at their own instants)."""
    if not first.size or not width:
        return
    f0 = int(first[0])
    if (first == f0).all():
        src = src[..., f0:f0 + width]
        dst[...] = src if src.ndim == 2 else src.transpose(1, 0, 2)
        return
    for f in np.unique(first).tolist():
        rows = np.flatnonzero(first == f)
        part = src[..., rows, f:f + width]
        dst[rows] = part if part.ndim == 2 else part.transpose(1, 0, 2)


def _intake_kernel():
    """The compiled backend's module when the intake may use it (:data:`COMPILED_INTAKE`), else None."""
    return fast.kernel_module() if COMPILED_INTAKE else None


def _buffer_args(buf: _RowBuffer, lo: bool = False) -> tuple[np.ndarray, ...]:
    """A row buffer's arrays as :func:`.numba_kernel.add_part_runs` takes them (``lo`` too for the force)."""
    head = (buf.t, buf.v, buf.ok) + ((buf.lo,) if lo else ())
    return head + (buf.hi, buf.last, buf.has, buf.added)


def _compiled_args(rows: np.ndarray, counts: np.ndarray, t_ns: np.ndarray, *arrays: np.ndarray) -> bool:
    """Arrays the compiled intake takes as they are (one compiled variant): ``rows``, ``counts`` and ``t_ns``
    int64, and every array C-contiguous and writeable."""
    return rows.dtype == counts.dtype == t_ns.dtype == _INDEX_DTYPE and fast.loaded_layout(rows, counts, t_ns, *arrays)


def _in_order(t_ns: np.ndarray, counts: np.ndarray, rows: np.ndarray, bufs: tuple[_RowBuffer, ...] | None) -> bool:
    """Whether every run's stamps increase strictly and start after its row's newest stamp in ``bufs``
    (each row at most one run)."""
    if not t_ns.size:
        return True
    up = np.diff(t_ns) > 0
    ends = np.cumsum(counts)
    up[ends[:-1][ends[:-1] < t_ns.size] - 1] = True  # from one run's last stamp to the next run's first: any
    if not up.all():
        return False
    if bufs is not None:
        has = counts > 0
        first = t_ns[(ends - counts)[has]]
        r = rows[has]
        for buf in bufs:
            if np.any(buf.has[r] & (first <= buf.last[r])):
                return False
    return True


def _ns(seconds: float, key: str, allow_zero: bool = False) -> int:
    value = float(seconds)
    if not np.isfinite(value) or value < 0 or (value == 0 and not allow_zero):
        kind = "non-negative" if allow_zero else "positive"
        raise ConfigError(f"must be a {kind} duration in seconds, got {seconds!r}", key=key)
    return int(round(value * 1e9))
