"""Windows over streaming cell data: fixed (length, hop) or one exploration.

The window node feeds :class:`Windower` with :class:`CellChunk` objects (one
per received message) and asks it for finished windows.  Everything runs on
the *sensor time stamps*, never the wall clock, so live data, simulated time
and replayed bags give the same windows.

* Fixed mode: windows ``[t0 + k hop, t0 + k hop + length)``; a window is
  emitted once every live cell has sent vibration data of a later time
  (plus ``lateness_s``): cells whose messages travel separately (one per
  body part) are all in before it is cut, whatever order they arrive in.
  A cell more than :data:`WATERMARK_STALL_S` behind the most recent one is
  not waited for.
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
from .aggregation import CellSignals
from .robot import RobotDescription

__all__ = ["CellChunk", "Window", "Windower", "SampleStream", "GAP_PERIODS", "WATERMARK_STALL_S", "BUFFER_HEADROOM",
           "BUFFER_SLACK_S"]

#: Exploration mode judges contact only up to the time every cell has sent
#: force data for (the watermark), so the order in which cells' messages
#: arrive cannot change onset or release; a cell silent for longer than this
#: behind the most recent one (unplugged, dead) no longer holds it back.
WATERMARK_STALL_S = 0.5

#: A cell's buffers are sized when its first chunk arrives, from its cell
#: type's rates, for the longest span the windower keeps plus
#: :data:`BUFFER_SLACK_S` (the chunks of one drained batch), times this
#: headroom: the kept samples are moved down once per third of a buffer, and
#: the buffer never has to grow (growing by doubling left the window node
#: with buffers 2-4 times the data, filled over minutes).
BUFFER_HEADROOM = 1.5
#: Seconds of samples a buffer holds beyond the retained span [s].
BUFFER_SLACK_S = 2.0

#: A cell whose vibration samples leave a hole longer than this many sample
#: periods inside a window (or at its edges) is marked ``gap`` and counted.
GAP_PERIODS = 3.0


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
class Window:
    """One finished window, ready for :func:`~.aggregation.describe_window`."""

    start_ns: int
    end_ns: int
    exploration_id: int
    mode: str
    cells: dict[int, CellSignals] = field(default_factory=dict)


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


class _CellState:
    def __init__(self, n_s: int, n_v: int, dtype_s: np.dtype, dtype_v: np.dtype, n_extra: int = 0,
                 capacity: tuple[int, int, int] = (256, 256, 256)) -> None:
        cap_s, cap_v, cap_f = capacity
        self.vib = SampleStream(n_s, dtype_s, cap_s, touch=True)
        self.dfm = SampleStream(n_v, dtype_v, cap_v, touch=True)
        # extra channels ride on the deformation stamps (one value per deformation sample)
        self.extra = SampleStream(n_extra, np.float64, cap_v, touch=True) if n_extra else None
        self.tare: np.ndarray | None = None  # latest deformation tare reported
        self.force = SampleStream(1, np.float64, cap_f, touch=True)
        self.last_force_n = 0.0  # mean over the last ``smooth_s`` of force samples
        self.hot_until_ns: int | None = None  # last stamp of a chunk with a force at or above release
        self.below_since_ns: int | None = None


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
        self._now_ns = 0  # the time of the current exploration step
        self._swept_ns: int | None = None  # the watermark the state machine has run to
        self._stall_ns = int(round(WATERMARK_STALL_S * 1e9))
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
            st = self._cells[cell_id] = _CellState(vib.shape[0], dfm.shape[0], vib.dtype, dfm.dtype, n_extra,
                                                   self.buffer_capacity(cell_id))
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
        end = int(t_v[-1])
        self._latest_ns = end if self._latest_ns is None else max(self._latest_ns, end)
        return True

    def _update_last_force(self, st: _CellState) -> None:
        """The cell's mean finite force over the last ``smooth_s`` (kept when none is finite)."""
        fs = st.force
        last_f = fs.last_t_ns
        if last_f is None:
            return
        t = fs._t[fs._lo:fs._hi]
        i = int(t.searchsorted(last_f - self.smooth_ns, side="left"))
        j = int(t.searchsorted(last_f + 1, side="left"))
        recent = fs._v[0, fs._lo + i:fs._lo + j]
        if recent.size == 0:
            return
        total = np.add.reduce(recent)
        if math.isfinite(total):  # all finite: the mean of the finite ones is the plain mean
            st.last_force_n = float(total / recent.size)
            return
        finite = recent[np.isfinite(recent)]
        if finite.size:
            st.last_force_n = float(finite.mean())

    def _reset_time(self) -> None:
        self._swept_ns = None
        self._next_start_ns = None
        self._onset_ns = None
        self._emitted_current = False
        self._latest_ns = None

    # ----------------------------------------------------------------- output
    def poll(self) -> list[Window]:
        """Windows finished by the data received so far."""
        if self._latest_ns is None:
            return []
        out = self._poll_fixed() if self.mode == "fixed" else self._poll_exploration()
        self._trim()
        return out

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
            self._next_start_ns = int(min(firsts))
        watermark = self._vibration_watermark()
        while self._next_start_ns + self.length_ns + self.lateness_ns <= watermark:
            start = self._next_start_ns
            out.append(self._make_window(start, start + self.length_ns, 0, "fixed"))
            self._next_start_ns += self.hop_ns
        return out

    def _vibration_watermark(self) -> int:
        """The latest vibration stamp every live cell has reached (fixed windows close on it).

        A cell more than :data:`WATERMARK_STALL_S` behind the most recent one
        (unplugged, dead) is not waited for.
        """
        newest = self._latest_ns
        floor = newest - self._stall_ns
        lasts = [t for st in self._cells.values() if (t := st.vib.last_t_ns) is not None and t >= floor]
        return min(lasts) if lasts else newest

    def _watermark(self) -> int | None:
        """The latest time every live cell has force data for (None before any force).

        Decisions made on data up to here do not depend on how the cells'
        messages interleaved or were batched.  A cell more than
        :data:`WATERMARK_STALL_S` behind the most recent one is not waited for.
        """
        lasts = [st.force.last_t_ns for st in self._cells.values() if len(st.force)]
        if not lasts:
            return None
        newest = max(lasts)
        return min(t for t in lasts if t >= newest - self._stall_ns)

    def _force_at(self, st: _CellState, t_ns: int) -> float:
        """The cell's mean finite force over the ``smooth_s`` up to ``t_ns`` (its latest when it ends there)."""
        fs = st.force
        last = fs.last_t_ns
        if last is None or last <= t_ns:
            return st.last_force_n
        t, lo = fs._t, fs._lo
        j = fs._hi
        while j > lo and t[j - 1] > t_ns:  # a cell is ahead of the watermark by a few samples: walk back
            j -= 1
        i = lo + int(t[lo:j].searchsorted(t_ns - self.smooth_ns, side="left"))
        recent = fs._v[0, i:j]
        if recent.size:
            total = np.add.reduce(recent)
            if math.isfinite(total):
                return float(total / recent.size)
            finite = recent[np.isfinite(recent)]
            if finite.size:
                return float(finite.mean())
        before = fs._v[0, lo:j]  # none finite in the last smooth_s: the last finite one
        finite = before[np.isfinite(before)]
        return float(finite[-1]) if finite.size else 0.0

    def _contact_at(self, t_ns: int) -> tuple[bool, bool]:
        """(any cell at or above onset, all cells below release) at ``t_ns``."""
        forces = [self._force_at(st, t_ns) for st in self._cells.values()]
        if not forces:
            return False, True
        return max(forces) >= self.onset_n, max(forces) < self.release_n

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
        if self._swept_ns is None:  # from the first force sample held
            t = min(int(st.force._t[st.force._lo]) for st in self._cells.values() if len(st.force)) - 1
        else:
            t = min(self._swept_ns, now)
        while True:
            nxt = self._next_event(t, now)
            if nxt is None:
                break
            out += self._step(nxt)
            t = nxt
        out += self._step(now)
        self._swept_ns = now
        return out

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
        hot = [st for st in self._cells.values() if st.hot_until_ns is not None and st.hot_until_ns >= since]
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
        return np.array([m if k > 0 else self._force_at(st, int(q)) for m, k, q in zip(mean, n, times_ns)])

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
        for st in self._cells.values():
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
        return best

    def _release_time(self) -> int:
        """First stamp after which every cell's smoothed force stayed below release."""
        best = self._onset_ns
        for st in self._cells.values():
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
        if end_ns - start < self.min_ns:
            self.faults["exploration_too_short"] += 1
            return None
        return self._make_window(start, end_ns, self._exploration_id, "exploration")

    def _make_window(self, start: int, end: int, exploration_id: int, mode: str) -> Window:
        w = Window(start, end, exploration_id, mode)
        for cid, st in self._cells.items():
            tv, v, okv = st.vib.between(start, end)
            if tv.size == 0:
                continue
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
                    continue
            gap = self._has_gap(cid, tv, start, end)
            if gap:
                self.faults["gap"] += 1
            w.cells[cid] = CellSignals(v, tv, d, td, f[0], valid, gap, n_bad, x, st.tare)
        return w

    def _has_gap(self, cell_id: int, t_ns: np.ndarray, start: int, end: int) -> bool:
        """A hole of more than :data:`GAP_PERIODS` vibration periods inside the window."""
        part, _ = self._index[cell_id]
        limit = GAP_PERIODS * 1e9 / self.robot.cell_types[part.cell_type].vibration.rate_hz
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
        for st in self._cells.values():
            for stream in (st.vib, st.dfm, st.force, st.extra):
                if stream is not None:
                    stream.trim_before(horizon)

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
        return sum(s.nbytes for st in self._cells.values() for s in (st.vib, st.dfm, st.force, st.extra)
                   if s is not None)

    @property
    def exploration_id(self) -> int:
        """Id of the current (or last) exploration; 0 before the first."""
        return self._exploration_id

    @property
    def in_contact(self) -> bool:
        """True while an exploration is open."""
        return self._onset_ns is not None


def _ns(seconds: float, key: str, allow_zero: bool = False) -> int:
    value = float(seconds)
    if not np.isfinite(value) or value < 0 or (value == 0 and not allow_zero):
        kind = "non-negative" if allow_zero else "positive"
        raise ConfigError(f"must be a {kind} duration in seconds, got {seconds!r}", key=key)
    return int(round(value * 1e9))
