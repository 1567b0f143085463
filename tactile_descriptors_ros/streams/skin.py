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
* keeps the force baseline (start tare, ``~/tare``: the resting level of
  :func:`~..core.tare.resting_level` over the last window of force samples) and cuts each cell's
  accelerometer samples into ``batch_s`` batches with the force and
  proximity samples of the same span (:class:`~..nodes.conversions.SkinFrame`).
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ..codecs.sequence import SequenceTracker
from ..codecs.skin import NO_STAMP, NOMINAL_RATE_HZ, Modality, SkinSampleBatch
from ..core.tare import resting_level
from ..errors import SignalError
from ..markers import INVALID_COUNT
from .clock import DeviceClock
from .frames import SkinFrame

__all__ = ["SkinStream", "CellState", "RECENT_FORCE", "drain_frames", "READ_FRAMES", "MAX_READ_FRAMES"]

#: Frames asked of a message transport per ``recv_batch`` call.
READ_FRAMES = 65536
#: Most frames one read keeps (1.5 s of a 116-cell skin): a driver further behind sheds the oldest, counted.
MAX_READ_FRAMES = 262144


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


class _Stream:
    """Pending samples of one modality of one cell: time stamps and counts, as a list of array pieces."""

    __slots__ = ("t", "v")

    def __init__(self) -> None:
        self.t: list[np.ndarray] = []
        self.v: list[np.ndarray] = []

    def add(self, t_ns: np.ndarray, values: np.ndarray) -> None:
        self.t.append(t_ns)
        self.v.append(values)

    def clear(self) -> None:
        self.t, self.v = [], []

    def __bool__(self) -> bool:
        return bool(self.t)

    def arrays(self, width: int) -> tuple[np.ndarray, np.ndarray]:
        """All pending samples, sorted by time (late, reordered frames back in place)."""
        if not self.t:
            return np.zeros(0, np.int64), np.zeros((0, width), np.int64)
        t = np.concatenate(self.t) if len(self.t) > 1 else self.t[0]
        v = np.concatenate(self.v) if len(self.v) > 1 else self.v[0]
        order = np.argsort(t, kind="stable")
        return t[order], v[order]

    def keep(self, t_ns: np.ndarray, values: np.ndarray) -> None:
        """Replace the pending samples by these (sorted) ones."""
        self.t, self.v = ([t_ns], [values]) if t_ns.size else ([], [])


@dataclass
class CellState:
    """One served cell: pending samples per modality, the last temperature, tare and counters."""

    cell_id: int
    body_part: str
    frame_id: str
    accel: _Stream = field(default_factory=_Stream)  # (t_ns, (x, y, z))
    force: _Stream = field(default_factory=_Stream)  # (t_ns, (f0, f1, f2))
    proximity: _Stream = field(default_factory=_Stream)  # (t_ns, p)
    temperature_c: float = float("nan")
    recent_force_t: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))  # last 500 force samples
    recent_force_v: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.int64))
    tare: np.ndarray = field(default_factory=lambda: np.zeros(3))
    tared: bool = False
    first_t_ns: int | None = None
    last_accel_t_ns: int | None = None
    sequence: int = 0
    lost: int = 0
    lost_since_msg: int = 0
    samples: int = 0
    messages: int = 0
    last_monotonic: float | None = None


#: Force samples kept per cell for ~/tare and the contact check.
RECENT_FORCE = 500


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
    """

    def __init__(self, cells: dict[int, tuple[str, str]], accel_rate_hz: float, force_rate_hz: float,
                 batch_s: float, stamp_source: str, resync_s: float, tare_on_start_s: float,
                 now_ns: Callable[[], int], faults: Counter, log: Callable[[str, str], None] | None = None) -> None:
        self.accel_rate_hz = float(accel_rate_hz)
        self.force_rate_hz = float(force_rate_hz)
        self.batch_s = float(batch_s)
        self.stamp_source = stamp_source
        self.resync_s = float(resync_s)
        self.tare_on_start_s = float(tare_on_start_s)
        self._now = now_ns
        self.faults = faults
        self._log = log or (lambda level, text: None)
        self.cells = {cid: CellState(cid, part, frame_id) for cid, (part, frame_id) in cells.items()}
        self._cell_list = list(self.cells.values())
        self._cell_index = np.full(0x10000, -1, dtype=np.int64)
        for i, cell in enumerate(self._cell_list):
            self._cell_index[cell.cell_id] = i
        k = 4 * len(self._cell_list)
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
        """Take the samples of one read; return the batches completed, per cell.

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
        return self._add_batch(ci, batch, arrival_ns)

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
            t = batch.stamp_ns[order].copy()
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
        # into the cells' buffers
        vals = batch.values[order]
        cell_of = gk // 4
        mono = time.monotonic()
        lost_per_group = np.add.reduceat(lost, starts)
        touched: dict[int, CellState] = {}
        for _g, (c, m, a, b, nl) in enumerate(zip(cell_of.tolist(), (gk % 4 + 1).tolist(), starts.tolist(),
                                                 ends.tolist(), lost_per_group.tolist())):
            cell = self._cell_list[c]
            tt, vv = t[a:b], vals[a:b]
            cell.lost += nl
            cell.lost_since_msg += nl
            cell.samples += b - a
            cell.last_monotonic = mono
            if keep is not None and not keep[a:b].all():
                tt, vv = tt[keep[a:b]], vv[keep[a:b]]
                if not tt.size:
                    continue
            if cell.first_t_ns is None:
                cell.first_t_ns = int(tt[0])
            if m == Modality.ACCEL:
                cell.accel.add(tt, vv)
                last = int(tt.max())
                cell.last_accel_t_ns = last if cell.last_accel_t_ns is None else max(last, cell.last_accel_t_ns)
            elif m == Modality.FORCE:
                cell.force.add(tt, vv)
                cell.recent_force_t = np.concatenate([cell.recent_force_t, tt])[-RECENT_FORCE:]
                cell.recent_force_v = np.concatenate([cell.recent_force_v, vv])[-RECENT_FORCE:]
            elif m == Modality.PROXIMITY:
                cell.proximity.add(tt, vv[:, :1])
            else:
                cell.temperature_c = float(vv[-1, 0]) * 0.01
            touched[c] = cell
        out: list[tuple[CellState, SkinFrame]] = []
        for cell in touched.values():
            out += self._cut(cell)
        return out

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

    def _cut(self, cell: CellState) -> list[tuple[CellState, SkinFrame]]:
        """Every complete ``batch_s`` of a cell's accelerometer samples, one batch each."""
        out: list[tuple[CellState, SkinFrame]] = []
        if not cell.accel:
            return out
        if not cell.tared and self.tare_on_start_s > 0:
            if cell.last_accel_t_ns - cell.first_t_ns >= self.tare_on_start_s * 1e9:
                ok, why = self.tare_cell(cell, self.tare_on_start_s)
                if not ok:
                    self._log("warning", f"cell {cell.cell_id}: start tare failed: {why}")
                    cell.tared = True  # publish anyway, untared (the diagnostics say so)
            cell.accel.clear()
            cell.force.clear()
            cell.proximity.clear()
            return out
        period_ns = 1e9 / self.accel_rate_hz
        batch_ns = self.batch_s * 1e9
        acc_t, acc_v = cell.accel.arrays(3)
        if acc_t[-1] - acc_t[0] + period_ns < batch_ns:
            cell.accel.keep(acc_t, acc_v)
            return out
        f_t, f_v = cell.force.arrays(3)
        p_t, p_v = cell.proximity.arrays(1)
        while acc_t.size and acc_t[-1] - acc_t[0] + period_ns >= batch_ns:
            t0 = int(acc_t[0])
            end = t0 + batch_ns - period_ns / 2  # this message: accelerometer samples of [t0, t0 + batch_s)
            na = int(np.searchsorted(acc_t, end, side="right"))
            nf = int(np.searchsorted(f_t, end, side="right"))
            np_ = int(np.searchsorted(p_t, end, side="right"))
            out.append((cell, self._frame(cell, t0, acc_t[:na], acc_v[:na], f_t[:nf], f_v[:nf],
                                          p_v[:np_, 0] if np_ == nf else None)))
            acc_t, acc_v = acc_t[na:], acc_v[na:]
            f_t, f_v, p_t, p_v = f_t[nf:], f_v[nf:], p_t[np_:], p_v[np_:]
        cell.accel.keep(acc_t, acc_v)
        cell.force.keep(f_t, f_v)
        cell.proximity.keep(p_t, p_v)
        return out

    def _frame(self, cell: CellState, t0: int, acc_t: np.ndarray, acc_v: np.ndarray, f_t: np.ndarray,
               f_v: np.ndarray, prox: np.ndarray | None) -> SkinFrame:
        frame = SkinFrame(
            stamp_ns=t0,
            accel=acc_v.T.astype(np.int16),
            accel_offset_ns=acc_t - t0,
            force=f_v.T.astype(np.uint16),
            force_offset_ns=f_t - t0,
            proximity=np.zeros(0, np.uint16) if prox is None else prox.astype(np.uint16),
            temperature_c=cell.temperature_c, sequence=cell.sequence, bad_frames=cell.lost_since_msg)
        cell.lost_since_msg = 0
        cell.sequence += 1
        return frame

    def force_n(self, cell: CellState, force_n_per_count: float) -> float | None:
        """Tared mean force of a cell's last five force samples [N] (``None`` before any)."""
        if not cell.recent_force_t.size:
            return None
        last = cell.recent_force_v[-5:].astype(np.float64)
        return float(np.mean(last - cell.tare[None, :])) * force_n_per_count

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
        if not cell.recent_force_t.size:
            return False, "no force samples yet"
        newest = cell.recent_force_t[-1]
        vals = cell.recent_force_v[cell.recent_force_t >= newest - window_s * 1e9]
        if len(vals) < 3:
            return False, f"only {len(vals)} force samples in the last {window_s} s"
        forces = np.where(vals == INVALID_COUNT, np.nan, vals.astype(np.float64)).T  # (3, samples)
        try:
            lvl = resting_level(forces, rest_percentile=rest_percentile)
        except SignalError as e:
            return False, str(e)
        cell.tare = lvl.reference
        cell.tared = True
        return True, "ok"
