"""The skin-cell stream: decoded samples -> unwrap -> lost frames -> stamps -> tare -> ``batch_s`` batches.

:class:`SkinStream` takes the :class:`~..codecs.skin.SkinSampleBatch` of one
read (CAN or serial, any cells and modalities mixed) and, for every (cell,
modality) at once with array operations:

* unwraps the 8-bit sequence numbers with the one
  :class:`~.sequence.SequenceTracker`, using the samples' bus times (or the
  arrival time of the read) as well as their numbers, so a cell silent for
  longer than a wrap (256 ms at 1 kHz) comes back with a gap of the right
  length, never a shifted clock;
* counts lost frames (jumps beyond the highest number seen);
* stamps the samples: ``clock`` takes each cell and modality's sequence
  number times the nominal period as its device clock and carries it to the
  host clock with one :class:`~.clock.DeviceClock` offset per cell and
  modality, updated by every read (the least delay between a sample and the
  read that returned it), so a stamp is the acquisition time and never later
  than its read; ``device`` uses the bus times (a sample without one is
  extrapolated from the nearest stamped sample of its cell and modality);
* keeps the force baseline of every cell (start tare, ``~/tare``: the
  resting level of :func:`~..core.tare.resting_level` over the last window
  of force samples);
* cuts each body part's samples on one grid of ``batch_s`` of sample time
  and hands out a part's samples as one
  :class:`~.skin_parts.SkinPartFrames` (one run per cell: accelerometer,
  force and proximity samples of the same span) once every cell of the
  part that is sending has passed the end of a batch -- all of it with
  array operations over the read, no Python object per cell or sample.  A
  message holds at most :data:`MAX_MESSAGE_BYTES` of samples (whole
  batches): a part that fell behind goes out in several messages.

After the unwrapping, the lost frames, ``clock`` stamps and per-cell state
of a read are one compiled pass (``numba_kernel.skin_stamp_add``, loaded by
:func:`load_compiled`) once no cell waits for its start tare; the numpy code
stays the reference (:data:`COMPILED_STAMPING`).
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable

import numpy as np

from ..codecs.sequence import SequenceTracker
from ..codecs.skin import NO_STAMP, NOMINAL_RATE_HZ, Modality, SkinSampleBatch
from ..core import fast
from ..core.tare import resting_level
from ..errors import SignalError
from ..markers import INVALID_COUNT
from .clock import DeviceClock
from .frames import SkinFrame
from .skin_parts import SkinPartFrames

__all__ = ["SkinStream", "CellState", "RECENT_FORCE", "drain_frames", "load_compiled", "COMPILED_STAMPING", "READ_FRAMES",
           "MAX_READ_FRAMES", "MAX_BACKLOG_S", "MAX_MESSAGE_BYTES"]

#: Frames asked of a message transport per ``recv_batch`` call.
READ_FRAMES = 65536
#: Most frames one read keeps by default; a driver sizes it from its bus (:data:`MAX_BACKLOG_S` of frames).
MAX_READ_FRAMES = 131072
#: Seconds of frames one read keeps: a driver further behind real time sheds the older ones (counted), so
#: that it catches up at once and the messages it publishes after a stall stay few.
MAX_BACKLOG_S = 0.25
#: Largest body part message in sample bytes (whole batches; at least one batch): 64 kB.
MAX_MESSAGE_BYTES = 65536
#: Bytes of one accelerometer sample (x, y, z, offset) and one force sample (3 sensors, offset, proximity).
_ACCEL_BYTES, _FORCE_BYTES = 14, 16


def drain_frames(transport, timeout_s: float, chunk: int = READ_FRAMES,
                 limit: int = MAX_READ_FRAMES) -> tuple[np.ndarray, int]:
    """Every frame queued on a message transport, the newest ``limit`` of them, and how many were shed.

    Waits up to ``timeout_s`` for the first frame, then takes what is queued
    without waiting, ``chunk`` frames per call, until a call returns fewer.
    A read must end with the newest frame the transport holds: its arrival
    times the device clocks (:class:`~.clock.DeviceClock`), and a read that
    stopped at ``chunk`` frames of a backlog would anchor them late.  A
    backlog beyond ``limit`` frames (a driver stopped or starved for
    seconds) keeps only its newest ``limit``: the older ones are shed (the
    sequence numbers count them as lost) so that the work of one read and
    the messages it makes stay bounded.
    """
    parts: list[np.ndarray] = []
    total = shed = 0
    frames = transport.recv_batch(chunk, timeout_s)
    while True:
        parts.append(frames)
        total += len(frames)
        while len(parts) > 1 and total - len(parts[0]) >= limit:
            total -= len(parts[0])
            shed += len(parts.pop(0))
        if len(frames) < chunk:
            break
        frames = transport.recv_batch(chunk, 0.0)
    out = parts[0] if len(parts) == 1 else np.concatenate(parts)
    if len(out) > limit:
        shed += len(out) - limit
        out = out[len(out) - limit:]
    return out, shed


class CellState:
    """One served cell, as the driver's diagnostics and ``~/tare`` see it (views of the stream's arrays)."""

    __slots__ = ("_s", "_i", "cell_id", "body_part", "frame_id")

    def __init__(self, stream: SkinStream, index: int, cell_id: int, body_part: str, frame_id: str) -> None:
        self._s, self._i = stream, index
        self.cell_id, self.body_part, self.frame_id = cell_id, body_part, frame_id

    @property
    def lost(self) -> int:
        """Frames lost on the bus (sequence gaps of its modalities)."""
        return int(self._s._lost[self._i])

    @property
    def samples(self) -> int:
        return int(self._s._samples[self._i])

    @property
    def messages(self) -> int:
        """Batches (runs) of this cell handed out."""
        return int(self._s._runs[self._i])

    @property
    def sequence(self) -> int:
        """Number of the next run."""
        return int(self._s._runs[self._i])

    @property
    def tared(self) -> bool:
        return bool(self._s._tared[self._i])

    @property
    def tare(self) -> np.ndarray:
        """Force baseline of the three sensors [counts]."""
        return self._s._tare[self._i].copy()

    @property
    def temperature_c(self) -> float:
        return float(self._s._temperature[self._i])

    @property
    def last_monotonic(self) -> float | None:
        """Host (monotonic) time of the last read with a sample of this cell."""
        t = float(self._s._last_mono[self._i])
        return None if np.isnan(t) else t


#: Force samples kept per cell for ~/tare and the contact check.
RECENT_FORCE = 500


#: Whether :class:`SkinStream` may stamp a read's samples in one compiled pass when the backend is loaded (the
#: tests switch it off to compare both paths).
COMPILED_STAMPING = True


#: ``skin_stamp_add``'s sample times when it makes them (``clock``)
_NO_TIMES = np.zeros(0, np.int64)


def _stream_kernel():
    """The compiled backend's module when the stream may use it (:data:`COMPILED_STAMPING`), else None."""
    return fast.kernel_module() if COMPILED_STAMPING else None


def load_compiled() -> bool:
    """Load the compiled stamping now (from the on-disk cache ``make setup`` fills) rather than on a stream's
    first read, whose frames would queue meanwhile: a skin driver calls this before it opens its bus.  Returns
    whether it serves (False where numpy does)."""
    kernel = _stream_kernel()
    if kernel is None:
        return False
    fast.warm_up_stream(kernel)
    return True


class _Pending:
    """Samples waiting to be cut, all cells of the stream together: stamps, cell index, values."""

    __slots__ = ("t", "c", "v")

    def __init__(self, width: int, dtype) -> None:
        self.t = np.zeros(0, np.int64)
        self.c = np.zeros(0, np.int64)
        self.v = np.zeros((0, width), dtype)

    def add(self, t: np.ndarray, c: np.ndarray, v: np.ndarray) -> None:
        if t.size:
            self.t = np.concatenate([self.t, t]) if self.t.size else t
            self.c = np.concatenate([self.c, c]) if self.c.size else c
            self.v = np.concatenate([self.v, v]) if self.v.size else v

    def take(self, sel: np.ndarray, group: np.ndarray, n_groups: int) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """The samples ``sel`` (a mask) selects, removed, split by ``group`` (each sample's, ``0..n_groups-1``):
        one ``(t, c, v)`` per group, its samples in their order here."""
        idx = np.flatnonzero(sel)
        g = group[idx]
        idx = idx[np.argsort(g, kind="stable")]
        t, c, v = self.t[idx], self.c[idx], self.v[idx]
        keep = ~sel
        self.t, self.c, self.v = self.t[keep], self.c[keep], self.v[keep]
        bounds = np.cumsum(np.bincount(g, minlength=n_groups)).tolist()
        out, lo = [], 0
        for hi in bounds:
            out.append((t[lo:hi], c[lo:hi], v[lo:hi]))
            lo = hi
        return out

    def drop_cells(self, mask_of_cell: np.ndarray) -> None:
        keep = ~mask_of_cell[self.c]
        self.t, self.c, self.v = self.t[keep], self.c[keep], self.v[keep]


class SkinStream:
    """Skin samples of the served cells -> per-cell batches (see the module docstring).

    Parameters
    ----------
    cells : mapping of cell id to (body part, frame id)
        The served cells.
    accel_rate_hz, force_rate_hz : float
        Nominal sample rates (proximity runs with force; temperature at its nominal rate).
    batch_s : float
        Sample time per batch and cell [s].
    stamp_source : {"clock", "device"}
    resync_s : float
        Re-anchor a ``clock`` offset after a device clock jump of more than this [s] (0 = never).
    tare_on_start_s : float
        Force baseline from the first samples [s] (nothing is emitted before); 0 = off.
    now_ns : callable() -> int
        The host (node) clock [ns] of ``clock`` stamps.
    faults : collections.Counter
        Shared fault counters (``clock_resync``, ``no_device_time``).
    log : callable(level, text), optional
        Where start-tare warnings go.
    scales : (float, float, float), optional
        ``accel_mps2_per_count``, ``force_n_per_count``, ``proximity_per_count`` of the messages.
    wait_s : float, optional
        A cell whose newest sample is this far behind its body part's newest
        is not waited for (default: two batches).
    """

    def __init__(self, cells: dict[int, tuple[str, str]], accel_rate_hz: float, force_rate_hz: float,
                 batch_s: float, stamp_source: str, resync_s: float, tare_on_start_s: float,
                 now_ns: Callable[[], int], faults: Counter, log: Callable[[str, str], None] | None = None,
                 scales: tuple[float, float, float] = (0.0, 0.0, 0.0), wait_s: float | None = None) -> None:
        self.accel_rate_hz = float(accel_rate_hz)
        self.force_rate_hz = float(force_rate_hz)
        self.batch_s = float(batch_s)
        self.stamp_source = stamp_source
        self.resync_s = float(resync_s)
        self.tare_on_start_s = float(tare_on_start_s)
        self._now = now_ns
        self.faults = faults
        self._log = log or (lambda level, text: None)
        self.scales = tuple(float(x) for x in scales)
        self._batch_ns = max(1, int(round(self.batch_s * 1e9)))
        self._wait_ns = int(round((2 * self.batch_s if wait_s is None else wait_s) * 1e9))
        self._ids = np.array(list(cells), np.int64)
        n = self._ids.size
        self._parts = list(dict.fromkeys(part for part, _ in cells.values()))
        self._part_of = np.array([self._parts.index(part) for part, _ in cells.values()], np.int64)
        self.cells = {cid: CellState(self, i, cid, part, frame_id)
                      for i, (cid, (part, frame_id)) in enumerate(cells.items())}
        self._cell_list = list(self.cells.values())
        self._cell_index = np.full(0x10000, -1, dtype=np.int64)
        self._cell_index[self._ids] = np.arange(n)
        # per cell: counters, tare, the newest stamps (the cut), the last temperature and force samples
        self._lost = np.zeros(n, np.int64)
        self._lost_since = np.zeros(n, np.int64)  # lost since the cell's last run
        self._samples = np.zeros(n, np.int64)
        self._runs = np.zeros(n, np.int64)
        self._last_mono = np.full(n, np.nan)
        self._temperature = np.full(n, np.nan)
        self._tare = np.zeros((n, 3))
        self._tared = np.zeros(n, bool)
        self._first_t = np.zeros(n, np.int64)
        self._has_first = np.zeros(n, bool)
        self._last_a = np.zeros(n, np.int64)  # newest accelerometer stamp
        self._has_a = np.zeros(n, bool)
        self._last_f = np.zeros(n, np.int64)  # newest force stamp
        self._has_f = np.zeros(n, bool)
        self._recent_t = np.zeros((n, RECENT_FORCE), np.int64)  # ring of the last force samples
        self._recent_v = np.zeros((n, RECENT_FORCE, 3), np.int64)
        self._recent_pos = np.zeros(n, np.int64)
        self._recent_n = np.zeros(n, np.int64)
        self._acc = _Pending(3, np.int64)
        self._force = _Pending(3, np.int64)
        self._prox = _Pending(1, np.int64)
        k = 4 * n
        # per cell and modality: the highest sequence number seen (lost frames), the device clock's offset
        # (clock stamps), the last bus time and its sequence number (device stamps without a bus time)
        self._clk = {"last": np.zeros(k, np.int64), "have": np.zeros(k, bool),
                     "bus_t": np.zeros(k, np.int64), "bus_seq": np.zeros(k, np.int64), "bus_have": np.zeros(k, bool),
                     "st_t": np.zeros(k, np.int64), "st_seq": np.zeros(k, np.int64), "st_have": np.zeros(k, bool)}
        self.clock = DeviceClock(k, jump_ns=int(round(self.resync_s * 1e9)))
        self._period_ns = 1e9 / np.array([self.accel_rate_hz, self.force_rate_hz, self.force_rate_hz,
                                          NOMINAL_RATE_HZ[Modality.TEMPERATURE]])
        # duplicates were dropped by the codec: no duplicate memory, only unwrapping
        self.tracker = SequenceTracker(256, window=0)
        self.other_part_frames: Counter[int] = Counter()

    def rates_hz(self) -> dict[Modality, float]:
        """The sample rate of each modality (for the codecs' own unwrapping)."""
        return {Modality(m + 1): 1e9 / p for m, p in enumerate(self._period_ns)}

    def resume(self) -> None:
        """The device was reopened: ``clock`` offsets are estimated afresh from the next read."""
        self.clock.reset()
        self._clk["bus_have"][:] = False
        self._clk["st_have"][:] = False  # a new offset may place the new samples anywhere after the absence

    def add(self, batch: SkinSampleBatch, arrival_ns: int | None = None) -> list[tuple[CellState, SkinFrame]]:
        """:meth:`add_parts`, each message's runs as per-cell ``(cell, SkinFrame)`` (tests, tools)."""
        return [(self.cells[cid], frame) for part in self.add_parts(batch, arrival_ns)
                for cid, frame, _ in part.frames()]

    def add_parts(self, batch: SkinSampleBatch, arrival_ns: int | None = None) -> list[SkinPartFrames]:
        """Take the samples of one read; return the body part messages they complete.

        ``arrival_ns`` is the host time of the read in the clock of the bus
        times (epoch nanoseconds, as python-can's time stamps): it times the
        samples for unwrapping when none of them came with a bus time (an
        adapter or framing without times), so each key keeps one clock.
        """
        if not len(batch):
            return []
        ci = self._cell_index[batch.cell_id]
        served = ci >= 0
        if not served.all():  # configured cells of body parts this stream does not serve
            ids, counts = np.unique(batch.cell_id[~served], return_counts=True)
            for c, k in zip(ids.tolist(), counts.tolist()):
                self.other_part_frames[c] += k
            batch, ci = batch.take(served), ci[served]
            if not len(batch):
                return []
        self._add_batch(ci, batch, arrival_ns)
        return self._cut(final=False)

    def flush(self) -> list[SkinPartFrames]:
        """Every pending sample as messages, whether or not its cells have passed its batch's end (a bus
        that went quiet: the last batches are not held back)."""
        return self._cut(final=True)

    def pending(self) -> int:
        """Samples waiting to be cut."""
        return int(self._acc.t.size + self._force.t.size + self._prox.t.size)

    def _add_batch(self, ci: np.ndarray, batch: SkinSampleBatch, arrival_ns: int | None
                   ) -> list[tuple[CellState, SkinFrame]]:
        """Add a batch of served samples: sequence unwrapping, lost frames and sample times for every
        (cell, modality) at once with array operations, then the samples to each cell's buffers."""
        key = ci * 4 + (batch.modality - 1)
        order = np.argsort(key, kind="stable")  # per cell and modality, in arrival order
        ks = key[order]
        n = ks.size
        starts = np.flatnonzero(np.r_[True, ks[1:] != ks[:-1]])
        ends = np.r_[starts[1:], n]
        lens = ends - starts
        gk = ks[starts]
        clk = self._clk
        have = clk["have"][gk]
        # unwrap the 8-bit sequence numbers with their times (a silence longer than a wrap is a gap)
        bus_t = batch.stamp_ns[order]
        stand_in = -1 if arrival_ns is None or (bus_t != NO_STAMP).any() else int(arrival_ns)
        t_ref = np.where(bus_t == NO_STAMP, stand_in, bus_t)
        _, useq = self.tracker.track_many(ks, batch.sequence[order] & 0xFF, int, t_ref, self._period_ns[ks % 4])
        kernel = _stream_kernel() if self.tare_on_start_s <= 0 or self._tared.all() else None
        if kernel is not None:  # nothing waits for a start tare: the rest in one compiled pass
            t = None if self.stamp_source == "clock" else \
                self._device_times(batch.stamp_ns[order], ks, useq, gk, starts, ends, lens)
            self._add_compiled(kernel, ks, useq, starts, ends, batch.values[order], t)
            return
        # frames lost: jumps beyond the highest number seen so far
        prev = np.empty(n, np.int64)
        prev[1:] = useq[:-1]
        prev[starts] = np.where(have, clk["last"][gk], useq[starts] - 1)
        offset = np.repeat(np.arange(gk.size, dtype=np.int64) << 42, lens)
        highest = np.maximum.accumulate(prev + offset) - offset
        lost = np.maximum(useq - highest - 1, 0)
        clk["have"][gk] = True
        clk["last"][gk] = np.maximum(highest[ends - 1], useq[ends - 1])
        # sample times
        keep = None
        if self.stamp_source == "clock":
            t = self._clock_times(ks, useq, starts)
            keep = self._monotonic(ks, useq, t, gk, starts)
        else:
            t = self._device_times(batch.stamp_ns[order], ks, useq, gk, starts, ends, lens)
        # per cell: counters, the last temperature, then the samples to the pending arrays
        vals = batch.values[order]
        cell_of = ks // 4
        mod = ks % 4 + 1
        n_cells = self._ids.size
        gcell = gk // 4
        np.add.at(self._lost, gcell, np.add.reduceat(lost, starts))
        np.add.at(self._lost_since, gcell, np.add.reduceat(lost, starts))
        self._samples += np.bincount(cell_of, minlength=n_cells)
        self._last_mono[gcell] = time.monotonic()
        temp = np.flatnonzero(mod == Modality.TEMPERATURE)[::-1]
        if temp.size:  # the last temperature of each cell (samples in arrival order within a key)
            cells, last = np.unique(cell_of[temp], return_index=True)
            self._temperature[cells] = vals[temp[last], 0] * 0.01
        if keep is not None:
            t, cell_of, mod, vals = t[keep], cell_of[keep], mod[keep], vals[keep]
        if not t.size:
            return
        first = np.full(n_cells, np.iinfo(np.int64).max)
        np.minimum.at(first, cell_of, t)
        new = ~self._has_first & (first < np.iinfo(np.int64).max)
        self._first_t[new] = first[new]
        self._has_first |= new
        a, f, p = (mod == Modality.ACCEL), (mod == Modality.FORCE), (mod == Modality.PROXIMITY)
        for sel, last, has in ((a, self._last_a, self._has_a), (f, self._last_f, self._has_f)):
            if sel.any():
                newest = np.full(n_cells, np.iinfo(np.int64).min)
                np.maximum.at(newest, cell_of[sel], t[sel])
                got = newest > np.iinfo(np.int64).min
                last[got] = np.where(has[got], np.maximum(last[got], newest[got]), newest[got])
                has |= got
        if f.any():
            self._remember_force(cell_of[f], t[f], vals[f, :3])
        # nothing is handed out before a cell's start tare: its samples until then only make the baseline
        if self.tare_on_start_s > 0 and not self._tared.all():
            self._start_tare()
            waiting = ~self._tared
            keep_s = ~waiting[cell_of]
            t, cell_of, vals, a, f, p = t[keep_s], cell_of[keep_s], vals[keep_s], a[keep_s], f[keep_s], p[keep_s]
        self._acc.add(t[a], cell_of[a], vals[a, :3])
        self._force.add(t[f], cell_of[f], vals[f, :3])
        self._prox.add(t[p], cell_of[p], vals[p, :1])

    def _device_times(self, bus_t: np.ndarray, ks: np.ndarray, useq: np.ndarray, gk: np.ndarray,
                      starts: np.ndarray, ends: np.ndarray, lens: np.ndarray) -> np.ndarray:
        """``device`` stamps of samples grouped by key: their bus times; where a sample has none, extrapolated
        from a stamped one of its key (this read's, else the last one's), else from the host clock."""
        clk = self._clk
        t = bus_t.copy()
        need = t == NO_STAMP
        if need.any():
            self.faults["no_device_time"] += int(need.sum())
            group = np.repeat(np.arange(gk.size), lens)
            need = self._extrapolate_device_times(t, need, useq, gk, group, starts, ends)
        if need.any():  # nothing stamped in this read: from the key's last bus time, else the host clock
            idx = np.flatnonzero(need)
            k = ks[idx]
            held = clk["bus_have"][k]
            a = idx[held]
            t[a] = clk["bus_t"][ks[a]] + np.rint((useq[a] - clk["bus_seq"][ks[a]])
                                                 * self._period_ns[ks[a] % 4]).astype(np.int64)
            b = idx[~held]
            if b.size:
                t[b] = self._clock_times(ks[b], useq[b], np.flatnonzero(np.r_[True, ks[b][1:] != ks[b][:-1]]))
        stamped = np.flatnonzero(~need)  # the last bus time of each key anchors its later samples
        if stamped.size:
            last = stamped[np.searchsorted(stamped, ends - 1, side="right") - 1]
            ok = (last >= starts) & (last >= 0)
            clk["bus_have"][gk[ok]] = True
            clk["bus_t"][gk[ok]] = t[last[ok]]
            clk["bus_seq"][gk[ok]] = useq[last[ok]]
        return t

    def _add_compiled(self, kernel, ks: np.ndarray, useq: np.ndarray, starts: np.ndarray, ends: np.ndarray,
                      vals: np.ndarray, t: np.ndarray | None) -> None:
        """What the rest of :meth:`_add_batch` does with no start tare pending, in one compiled pass
        (``numba_kernel.skin_stamp_add``; the numpy code is the reference the tests hold it to): ``clock`` stamps
        (``t`` None) are made in the pass, ``device`` stamps ``t`` come made."""
        n = ks.size
        out_t = np.empty((3, n), np.int64)
        out_c = np.empty((3, n), np.int64)
        out_v = np.empty((3, n, 3), np.int64)
        counts = np.zeros(5, np.int64)
        clk, clock = self._clk, self.clock
        given = _NO_TIMES if t is None else t
        kernel.skin_stamp_add(ks, useq, starts, ends, np.ascontiguousarray(vals, np.int64), given, self._period_ns,
                              clk["last"], clk["have"], clk["st_t"], clk["st_seq"], clk["st_have"], *clock.state(),
                              clock.drift, clock.jump_ns, clock.confirm_ns, int(self._now()),
                              self._lost, self._lost_since, self._samples, self._last_mono, time.monotonic(),
                              self._temperature, self._first_t, self._has_first, self._last_a, self._has_a,
                              self._last_f, self._has_f, self._recent_t, self._recent_v, self._recent_pos,
                              self._recent_n, out_t, out_c, out_v, counts)
        n_a, n_f, n_p, back, resyncs = counts.tolist()
        if t is None:
            clock.observations += starts.size
        if resyncs:
            clock.resyncs += resyncs
            self.faults["clock_resync"] += resyncs
        if back:
            self.faults["clock_step_back_samples"] += back
        self._acc.add(out_t[0, :n_a], out_c[0, :n_a], out_v[0, :n_a])
        self._force.add(out_t[1, :n_f], out_c[1, :n_f], out_v[1, :n_f])
        self._prox.add(out_t[2, :n_p], out_c[2, :n_p], out_v[2, :n_p, :1])

    def _remember_force(self, cells: np.ndarray, t: np.ndarray, v: np.ndarray) -> None:
        """The last :data:`RECENT_FORCE` force samples of each cell (``~/tare``, the contact check)."""
        order = np.argsort(cells, kind="stable")
        c, t, v = cells[order], t[order], v[order]
        starts = np.flatnonzero(np.r_[True, c[1:] != c[:-1]])
        size = np.diff(np.r_[starts, c.size])
        rank = np.arange(c.size) - np.repeat(starts, size)
        last = rank >= np.repeat(size, size) - RECENT_FORCE  # more than the ring holds: its newest only
        c, t, v, rank = c[last], t[last], v[last], rank[last]
        slot = (self._recent_pos[c] + rank) % RECENT_FORCE
        self._recent_t[c, slot] = t
        self._recent_v[c, slot] = v
        counts = np.bincount(cells, minlength=self._ids.size)
        self._recent_pos = (self._recent_pos + counts) % RECENT_FORCE
        self._recent_n = np.minimum(self._recent_n + counts, RECENT_FORCE)

    def _recent(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """A cell's remembered force samples, oldest first: stamps and (n, 3) counts."""
        n = int(self._recent_n[i])
        idx = (int(self._recent_pos[i]) - n + np.arange(n)) % RECENT_FORCE
        return self._recent_t[i, idx], self._recent_v[i, idx]

    def _start_tare(self) -> None:
        """Cells whose samples span ``tare_on_start_s`` take their force baseline (once each)."""
        due = ~self._tared & self._has_a & self._has_first & (
            self._last_a - self._first_t >= self.tare_on_start_s * 1e9)
        for i in np.flatnonzero(due).tolist():
            cell = self._cell_list[i]
            ok, why = self.tare_cell(cell, self.tare_on_start_s)
            if not ok:
                self._log("warning", f"cell {cell.cell_id}: start tare failed: {why}")
                self._tared[i] = True  # publish anyway, untared (the diagnostics say so)

    def _batch_ends(self, final: bool) -> np.ndarray:
        """Per body part, the time before which its samples are due: the end of the last whole batch every
        waited-for cell has passed (``final``: every sample).

        A cell has passed a time once its newest accelerometer and force
        samples are within one period of it (the next would be later); a
        cell whose newest sample is more than ``wait_s`` behind its part's
        newest is not waited for.
        """
        n_parts = len(self._parts)
        big = np.iinfo(np.int64).max
        if final:
            return np.full(n_parts, big)
        period_a, period_f = self._period_ns[0], self._period_ns[1]
        reach = np.where(self._has_a, self._last_a + int(period_a), big)
        reach = np.minimum(reach, np.where(self._has_f, self._last_f + int(period_f), big))
        newest = np.where(self._has_a, self._last_a, np.where(self._has_f, self._last_f, np.iinfo(np.int64).min))
        part_newest = np.full(n_parts, np.iinfo(np.int64).min)
        np.maximum.at(part_newest, self._part_of, newest)
        waited = (newest >= part_newest[self._part_of] - self._wait_ns) & (self._has_a | self._has_f)
        until = np.full(n_parts, big)
        np.minimum.at(until, self._part_of[waited], reach[waited])
        b = self._batch_ns
        return np.where(until < big, (until // b) * b, np.iinfo(np.int64).min)  # the end of the last whole batch

    def _cut(self, final: bool) -> list[SkinPartFrames]:
        """The messages due: per body part, its samples before :meth:`_batch_ends`, in whole batches."""
        out: list[SkinPartFrames] = []
        if not (self._acc.t.size or self._force.t.size):
            return out
        n_parts = len(self._parts)
        end = self._batch_ends(final)
        # every body part at once: the samples before their part's end; a part takes its proximity samples only
        # when it has accelerometer or force samples due
        part_a, part_f, part_p = (self._part_of[x.c] for x in (self._acc, self._force, self._prox))
        sel_a, sel_f = self._acc.t < end[part_a], self._force.t < end[part_f]
        due = np.zeros(n_parts, bool)
        due[part_a[sel_a]] = True
        due[part_f[sel_f]] = True
        if not due.any():
            return out
        sel_p = due[part_p] & (self._prox.t < end[part_p])
        acc = self._acc.take(sel_a, part_a, n_parts)
        force = self._force.take(sel_f, part_f, n_parts)
        prox = self._prox.take(sel_p, part_p, n_parts)
        for k in np.flatnonzero(due).tolist():
            out += self._messages(self._parts[k], acc[k], force[k], prox[k])
        if len(out) > n_parts:  # a backlog in several messages per part: in time order, the parts side by side
            out.sort(key=lambda m: m.stamp_ns)
        return out

    def _messages(self, part: str, acc, force, prox) -> list[SkinPartFrames]:
        """One body part's samples as messages of whole batches, at most :data:`MAX_MESSAGE_BYTES` each."""
        t_all = np.concatenate([acc[0], force[0]])
        slot = t_all // self._batch_ns
        lo, hi = int(slot.min()), int(slot.max())
        per_slot = (acc[0].size * _ACCEL_BYTES + force[0].size * _FORCE_BYTES) / (hi - lo + 1)
        span = max(1, int(MAX_MESSAGE_BYTES // max(per_slot, 1.0)))
        if hi - lo + 1 <= span:
            return [self._message(part, acc, force, prox)]
        out = []
        for first in range(lo, hi + 1, span):
            end = (first + span) * self._batch_ns
            start = first * self._batch_ns
            pieces = [tuple(x[(m[0] >= start) & (m[0] < end)] for x in m) for m in (acc, force, prox)]
            if pieces[0][0].size or pieces[1][0].size:
                out.append(self._message(part, *pieces))
        if len(out) > 1:
            self.faults["part_messages_split"] += len(out) - 1
        return out

    def _message(self, part: str, acc, force, prox) -> SkinPartFrames:
        """One message: a run per cell (accelerometer, force, proximity of its samples, in time order)."""
        (ta, ca, va), (tf, cf, vf), (tp, cp, vp) = acc, force, prox
        n = self._ids.size
        oa = np.lexsort((ta, ca))
        of = np.lexsort((tf, cf))
        ta, ca, va, tf, cf, vf = ta[oa], ca[oa], va[oa], tf[of], cf[of], vf[of]
        na = np.bincount(ca, minlength=n)
        nf = np.bincount(cf, minlength=n)
        cells = np.flatnonzero((na > 0) | (nf > 0))
        stamp = int(min(ta.min() if ta.size else np.iinfo(np.int64).max, tf.min() if tf.size else
                        np.iinfo(np.int64).max))
        npx = np.bincount(cp, minlength=n)
        if tp.size:  # proximity is one value per force sample: a run's, in time order, when its counts agree
            op = np.lexsort((tp, cp))
            cp, vp = cp[op], vp[op]
            same = npx == nf
            proximity = np.full(tf.size, INVALID_COUNT, np.uint16)
            ok_f = same[cf]
            proximity[ok_f] = vp[same[cp], 0]
        else:
            proximity = np.zeros(0, np.uint16)
        seq = self._runs[cells].copy()
        self._runs[cells] += 1
        bad = self._lost_since[cells].copy()
        self._lost_since[cells] = 0
        return SkinPartFrames(
            stamp_ns=stamp, body_part=part, cell_ids=self._ids[cells], sequence=seq, accel_count=na[cells],
            force_count=nf[cells], temperature_c=self._temperature[cells], force_tare_counts=self._tare[cells],
            bad_frames=bad, accel=va.T.astype(np.int16), accel_offset_ns=ta - stamp, force=vf.T.astype(np.uint16),
            force_offset_ns=tf - stamp, proximity=proximity, accel_mps2_per_count=self.scales[0],
            force_n_per_count=self.scales[1], proximity_per_count=self.scales[2], frame_id=part)

    def _extrapolate_device_times(self, t: np.ndarray, need: np.ndarray, useq: np.ndarray, gk: np.ndarray,
                                  group: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
        """``device`` stamps: a sample without a bus time (python-can's timestamp 0.0) gets the time of the
        nearest stamped sample of its cell and modality in this batch plus the sequence distance times the
        nominal period.  Fills ``t`` in place; returns the samples still without a time."""
        n = t.size
        pos = np.arange(n)
        stamped = np.where(~need, pos, -1)
        offset = np.repeat(starts, ends - starts)
        before = np.maximum.accumulate(stamped)  # nearest stamped sample at or before, any group
        after = np.minimum.accumulate(np.where(~need, pos, n)[::-1])[::-1]  # nearest at or after
        ref = np.where(before >= offset, before, np.where(after < np.repeat(ends, ends - starts), after, -1))
        fill = need & (ref >= 0)
        if fill.any():
            r = ref[fill]
            period = self._period_ns[gk[group[fill]] % 4]
            t[fill] = t[r] + np.rint((useq[fill] - useq[r]) * period).astype(np.int64)
        return need & ~fill

    def _monotonic(self, ks: np.ndarray, useq: np.ndarray, t: np.ndarray, gk: np.ndarray,
                   starts: np.ndarray) -> np.ndarray | None:
        """Which ``clock``-stamped samples to keep so that no cell and modality's stamps step back.

        When a read sees a smaller delay than any before, the offset drops and
        the new samples are stamped earlier than the previous ones were (those
        were late by the difference).  A sample newer in sequence than the
        last one stamped but not later in time is dropped and counted
        (``clock_step_back_samples``); a late, reordered frame (older in
        sequence) is kept, as before.  Returns None when every sample stays.
        """
        clk = self._clk
        had = clk["st_have"][ks]
        back = had & (useq > clk["st_seq"][ks]) & (t <= clk["st_t"][ks])
        keep = None
        if back.any():
            self.faults["clock_step_back_samples"] += int(back.sum())
            keep = ~back
        floor = np.iinfo(np.int64).min
        newest_t = np.maximum.reduceat(np.where(back, floor, t), starts)
        newest_q = np.maximum.reduceat(np.where(back, floor, useq), starts)
        upd = newest_t > floor
        k = gk[upd]
        clk["st_t"][k] = np.where(clk["st_have"][k], np.maximum(clk["st_t"][k], newest_t[upd]), newest_t[upd])
        clk["st_seq"][k] = np.where(clk["st_have"][k], np.maximum(clk["st_seq"][k], newest_q[upd]), newest_q[upd])
        clk["st_have"][k] = True
        return keep

    def _clock_times(self, keys: np.ndarray, useq: np.ndarray, starts: np.ndarray) -> np.ndarray:
        """``clock`` stamps of samples grouped by key (``starts``: each group's first sample).

        A key's device clock is its unwrapped sequence number times the
        nominal period; each key's newest device time in this read and the
        host (node) clock now update its :class:`~.clock.DeviceClock` offset
        before the samples are stamped, so no stamp is later than now.
        """
        dev = np.rint(useq * self._period_ns[keys % 4]).astype(np.int64)
        before = self.clock.resyncs
        self.clock.observe(keys[starts], np.maximum.reduceat(dev, starts), self._now())
        if self.clock.resyncs > before:
            self.faults["clock_resync"] += self.clock.resyncs - before
        return self.clock.to_host(keys, dev)

    def force_n(self, cell: CellState, force_n_per_count: float) -> float | None:
        """Tared mean force of a cell's last five force samples [N] (``None`` before any)."""
        t, v = self._recent(cell._i)
        if not t.size:
            return None
        last = v[-5:].astype(np.float64)
        return float(np.mean(last - self._tare[cell._i][None, :])) * force_n_per_count

    def tare_cell(self, cell: CellState, window_s: float, *, rest_percentile: float = 100.0) -> tuple[bool, str]:
        """Set a cell's force baseline to its resting level over its last ``window_s`` of force samples.

        The level is :func:`~..core.tare.resting_level` of the three force
        sensors (``INVALID_COUNT`` samples unreadable), so a span read offline
        gets the same level from the same samples.

        Parameters
        ----------
        cell : CellState
        window_s : float
            Force samples stamped within this long of the newest one [s].
        rest_percentile : float
            Share of the window known to rest: 100 for ``~/tare`` and the start
            tare, which take a window without contact.

        Returns
        -------
        (bool, str)
            Whether the cell was tared, and what was done or why not.
        """
        t, v = self._recent(cell._i)
        if not t.size:
            return False, "no force samples yet"
        vals = v[t >= t[-1] - window_s * 1e9]
        if len(vals) < 3:
            return False, f"only {len(vals)} force samples in the last {window_s} s"
        forces = np.where(vals == INVALID_COUNT, np.nan, vals.astype(np.float64)).T  # (3, samples)
        try:
            lvl = resting_level(forces, rest_percentile=rest_percentile)
        except SignalError as e:
            return False, str(e)
        self._tare[cell._i] = lvl.reference
        self._tared[cell._i] = True
        return True, "ok"
