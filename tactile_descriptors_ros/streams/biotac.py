"""BioTac streams: SPI sampling or the serial bridge -> frames -> lost frames, stamps, tare -> batches.

:class:`SpiFrameSource` runs the SPI sampling sequence (Cheetah, a simulated
SPI bus); :class:`BridgeFrameSource` reads our USB-serial bridge framing
(``docs/protocols.md``).  Both return :class:`ReadItem` objects: the frames
of one BioTac from one read with their device times and unwrapped sequence
numbers.  :class:`BiotacStream` takes them per sensor: counts lost frames,
stamps frames (``clock``: the device clock carried to the host clock by a
:class:`~.clock.DeviceClock` per BioTac, updated by every read, so a stamp
is the acquisition time and never later than the read that returned it;
``device``: as it is), holds the tare (start tare, ``~/tare``: the resting
level of :func:`~..core.tare.resting_level` over the last window of frames;
slow baseline tracking) and cuts batches of ``batch_frames``
consecutive frames (:class:`~..nodes.conversions.BioTacBatch`; a gap ends a
batch).  After the device was gone (:class:`~.link.DeviceLink`),
:meth:`BiotacStream.resume` counts the time it was missing as lost frames.
"""

from __future__ import annotations

import time
from collections import Counter, deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from ..codecs.biotac_spi import BiotacFrameDecoder, BiotacFrames, FramePattern, WordCounts
from ..codecs.bridge_serial import BridgeDecoder, BridgeFrameType
from ..codecs.sequence import Unwrapper
from ..core.tare import MIN_REST_SAMPLES, resting_level
from ..errors import CodecError, SignalError
from .clock import DeviceClock
from .frames import BioTacBatch

__all__ = ["ReadItem", "SpiFrameSource", "BridgeFrameSource", "SensorConfig", "SensorState", "BiotacStream",
           "RECENT_FRAMES"]

#: Frames kept per BioTac for ~/tare and the contact check.
RECENT_FRAMES = 2000


@dataclass
class ReadItem:
    """Frames of one BioTac from one read: decoded frames, their device times [ns] and sequence numbers."""

    chip_select: int
    frames: BiotacFrames
    device_t_ns: np.ndarray
    sequence: np.ndarray
    clock_restart: bool = False  # the device clock does not continue the previous read's (re-anchor it)


class SpiFrameSource:
    """SPI sampling (Cheetah, or a simulated SPI bus): one frame of every BioTac per :meth:`read`.

    The device clock is the frame count times the frame period; reads are
    paced to ``word_rate_hz`` (a real adapter paces itself; pacing then only
    sleeps when ahead of schedule).
    """

    def __init__(self, spi, pattern: FramePattern, chip_selects: Sequence[int], word_rate_hz: float,
                 decoder: BiotacFrameDecoder) -> None:
        from ..transports.biotac import read_frame, read_serial_number

        self._read_frame = read_frame
        self._read_serial = read_serial_number
        self.spi = spi
        self.pattern = pattern
        self.chip_selects = list(chip_selects)
        self.word_rate_hz = float(word_rate_hz)
        self.period_ns = int(round(pattern.slot_count / self.word_rate_hz * 1e9))
        self.decoder = decoder
        self.frame = 0
        self._t0: float | None = None
        self.overruns = 0
        self.serial_numbers: dict[int, str] = {}
        self.serial_errors: dict[int, str] = {}

    def read_serial_numbers(self) -> None:
        """Ask every BioTac for its serial number (failures kept in ``serial_errors``)."""
        for cs in self.chip_selects:
            try:
                self.serial_numbers[cs] = self._read_serial(self.spi, cs)
            except CodecError as exc:
                self.serial_errors[cs] = str(exc)

    def read(self) -> list[ReadItem]:
        """One frame of every BioTac."""
        now = time.monotonic()
        if self._t0 is None:
            self._t0 = now
        due = self._t0 + self.frame * self.period_ns * 1e-9
        if due > now:
            time.sleep(due - now)
        restart = False
        if due <= now and now - due > 0.5:  # fell behind by more than half a second: restart the schedule
            self.overruns += 1
            self._t0 = now - self.frame * self.period_ns * 1e-9
            restart = True  # nothing was sampled meanwhile: the frame clock paused while real time went on
        replies = self._read_frame(self.spi, self.pattern, self.chip_selects, self.word_rate_hz)
        k = self.frame
        self.frame += 1
        out = []
        for cs in self.chip_selects:
            frames = self.decoder.decode_many(cs, replies[cs], first_sequence=k)
            out.append(ReadItem(cs, frames, np.array([k * self.period_ns], np.int64), np.array([k], np.int64),
                                clock_restart=restart))
        return out


class BridgeFrameSource:
    """Our USB-serial bridge framing over a byte transport (serial, loopback, simulated).

    Sequence numbers (16 bits) and the bridge clock (32-bit microseconds)
    are unwrapped with :class:`~.sequence.Unwrapper` using time: the clock
    with the host time elapsed since the previous frame, the sequence number
    with the bridge time elapsed divided by the frame period, so a silence
    longer than half a wrap is still a gap of the right length.  A payload
    that is not exactly one frame of the configured pattern is a counted
    :class:`~..errors.FrameError` (``decode_errors``), never frames.
    """

    def __init__(self, stream, pattern: FramePattern, chip_selects: Sequence[int],
                 decoder: BiotacFrameDecoder, read_timeout_s: float = 0.05, frame_period_ns: float | None = None,
                 host_clock_ns: Callable[[], int] = time.monotonic_ns) -> None:
        self.stream = stream
        self.pattern = pattern
        self.chip_selects = set(int(c) for c in chip_selects)
        self.decoder = decoder
        self.bridge = BridgeDecoder()
        self.read_timeout_s = float(read_timeout_s)
        self.frame_period_ns = frame_period_ns
        self._host_ns = host_clock_ns
        self.serial_numbers: dict[int, str] = {}
        self.serial_errors: dict[int, str] = {}
        self.unconfigured_frames: Counter[int] = Counter()
        self.decode_errors = 0
        self.last_decode_error: str | None = None
        self.restart()

    def restart(self, stream=None) -> None:
        """Start over on a reopened device (``stream``: its new transport): fresh framing and counters' history."""
        if stream is not None:
            self.stream = stream
            self.bridge = BridgeDecoder()
        self._seq = {cs: Unwrapper(1 << 16) for cs in self.chip_selects}
        self._t = {cs: Unwrapper(1 << 32) for cs in self.chip_selects}
        self._host_last: dict[int, int] = {}

    def read_serial_numbers(self) -> None:
        """Serial numbers arrive as bridge frames; nothing to ask."""

    def read(self) -> list[ReadItem]:
        """The frames completed by the bytes available now (waits up to ``read_timeout_s``)."""
        data = self.stream.read(65536, self.read_timeout_s)
        if not data:
            return []
        host = self._host_ns()
        out: list[ReadItem] = []
        for fr in self.bridge.feed(data):
            cs = fr.chip_select
            if cs not in self.chip_selects:
                self.unconfigured_frames[cs] += 1
                continue
            if fr.kind == BridgeFrameType.SERIAL_NUMBER:
                try:
                    self.serial_numbers[cs] = fr.payload.decode("ascii")
                except UnicodeDecodeError:
                    self.serial_errors[cs] = f"serial number is not ASCII: {fr.payload!r}"
                continue
            t_clock, t_seq = self._t[cs], self._seq[cs]
            last_t = t_clock.value
            host_last = self._host_last.get(cs)
            t_us = t_clock(fr.t_us, 0.0 if host_last is None else (host - host_last) / 1000.0)
            self._host_last[cs] = host
            advance = 0.0
            if last_t is not None and self.frame_period_ns:
                advance = (t_us - last_t) * 1000.0 / self.frame_period_ns
            seq = t_seq(fr.sequence, advance)
            try:
                frames = self.decoder.decode_many(cs, fr.payload, first_sequence=seq, max_frames=1)
            except CodecError as exc:
                self.decode_errors += 1
                self.last_decode_error = str(exc)
                continue
            out.append(ReadItem(cs, frames, np.array([t_us * 1000], np.int64), np.array([seq], np.int64)))
        return out


@dataclass
class SensorConfig:
    """One BioTac as the robot description places it."""

    chip_select: int
    sensor_name: str
    body_part: str
    frame_id: str


@dataclass
class SensorState:
    """What the stream knows about one BioTac: pending frames, tare, counters."""

    cfg: SensorConfig
    frames: list[tuple[int, int, BiotacFrames]] = field(default_factory=list)  # (seq, stamp_ns, frames)
    # frames with a readable PDC, for ~/tare and the contact check: (stamp_ns, pdc) and, frame for frame,
    # that frame's electrodes (float64, NaN where unreadable)
    recent_pdc: deque = field(default_factory=lambda: deque(maxlen=RECENT_FRAMES))
    recent_el: deque = field(default_factory=lambda: deque(maxlen=RECENT_FRAMES))
    tare_pdc: float = 0.0
    tare_electrodes: np.ndarray | None = None
    tared: bool = False
    tracked_frames: int = 0
    counts: WordCounts = field(default_factory=WordCounts)
    frames_total: int = 0
    messages: int = 0
    lost_frames: int = 0
    gaps: int = 0
    resumed_gaps: int = 0
    last_gap_s: float | None = None
    next_seq: int | None = None
    last_host_ns: int | None = None
    resume_from_ns: int | None = None
    first_stamp_ns: int | None = None
    last_sample_ns: int | None = None  # stamp of the newest PAC sample taken (stamps never step back)


class BiotacStream:
    """Per-BioTac stream: lost frames -> stamps -> tare -> batches of consecutive frames.

    Parameters
    ----------
    sensors : mapping of chip select to SensorConfig
    pattern : FramePattern
    word_rate_hz : float
    batch_frames : int
        Frames per batch.
    stamp_source : {"clock", "device"}
        ``clock``: device time plus the :class:`~.clock.DeviceClock` offset
        estimated from every read; ``device``: device time as it is.
    resync_s : float
        Re-anchor a ``clock`` offset after a device clock jump of more than this (0 = never).
    tare_on_start_s : float
        Baseline from the first frames (nothing is emitted before); 0 = off.
    track_s, track_band_n : float
        Baseline tracking time constant [s] (0 = off) and the force band it works in [N].
    force_n_per_count : float
    now_ns : callable() -> int
        The host (node) clock [ns] of ``clock`` stamps, read once per read.
    faults : collections.Counter
        Shared fault counters (``clock_resync``).
    log : callable(level, text), optional
        Where start-tare messages go (``level`` "info" or "warning").
    """

    def __init__(self, sensors: dict[int, SensorConfig], pattern: FramePattern, word_rate_hz: float,
                 batch_frames: int, stamp_source: str, resync_s: float, tare_on_start_s: float, track_s: float,
                 track_band_n: float, force_n_per_count: float, now_ns: Callable[[], int], faults: Counter,
                 log: Callable[[str, str], None] | None = None) -> None:
        self.sensors = sensors
        self.pattern = pattern
        self.word_rate_hz = float(word_rate_hz)
        self.frame_period_ns = 1e9 / pattern.rates(word_rate_hz).frame_rate_hz
        self.batch_frames = int(batch_frames)
        self.stamp_source = stamp_source
        self.resync_s = float(resync_s)
        self.tare_on_start_s = float(tare_on_start_s)
        self.track_band_n = float(track_band_n)
        self.force_n_per_count = float(force_n_per_count)
        frame_hz = pattern.rates(word_rate_hz).frame_rate_hz
        # weight of one frame in the tracked baseline (exponential, time constant track_s)
        self.track_alpha = min(1.0, 1.0 / (frame_hz * track_s)) if track_s > 0 else 0.0
        self._now = now_ns
        self.faults = faults
        self._log = log or (lambda level, text: None)
        self._pac_off = pattern.pac_offsets_ns(word_rate_hz)
        self.state: dict[int, SensorState] = {cs: SensorState(cfg) for cs, cfg in sensors.items()}
        self._key = {cs: i for i, cs in enumerate(sorted(sensors))}
        self.clock = DeviceClock(len(self._key), jump_ns=int(round(self.resync_s * 1e9)))
        # a frame's newest sample, relative to its device time: its last word slot
        self._newest_ns = int(pattern.slot_offsets_ns(word_rate_hz)[-1])

    # ---------------------------------------------------------------- frames
    def observe(self, items: Sequence[ReadItem], host_ns: int | None = None) -> None:
        """Update the ``clock`` offsets with one read: each BioTac's newest sample against ``host_ns``.

        ``host_ns`` is the host (node) clock when the read returned (default:
        now).  :meth:`add_read` calls this before stamping the read's frames.
        """
        if self.stamp_source == "device":
            return
        newest: dict[int, int] = {}
        restart: set[int] = set()
        for item in items:
            if item.chip_select not in self._key or not len(item.device_t_ns):
                continue
            t = int(np.max(item.device_t_ns))
            newest[item.chip_select] = max(t, newest.get(item.chip_select, t))
            if item.clock_restart:
                restart.add(self._key[item.chip_select])
        if not newest:
            return
        if restart:
            self.clock.reset(np.fromiter(restart, np.int64))
        before = self.clock.resyncs
        keys = np.array([self._key[cs] for cs in newest], np.int64)
        dev = np.fromiter(newest.values(), np.int64, len(newest)) + self._newest_ns
        self.clock.observe(keys, dev, self._now() if host_ns is None else int(host_ns))
        if self.clock.resyncs > before:
            self.faults["clock_resync"] += self.clock.resyncs - before

    def stamp(self, chip_select: int, device_t_ns: int) -> int:
        """The time stamp of a frame of ``chip_select`` at device time ``device_t_ns`` (after :meth:`observe`)."""
        if self.stamp_source == "device":
            return int(device_t_ns)
        return int(self.clock.to_host(self._key[chip_select], int(device_t_ns)))

    def add_read(self, items: Sequence[ReadItem], host_ns: int | None = None,
                 now_ns: int | None = None) -> list[tuple[SensorState, BioTacBatch]]:
        """Take the frames of one read (every BioTac's); return the batches completed (sensor, batch).

        ``host_ns``: the monotonic host time of the read (lost frames across
        an absence); ``now_ns``: the node clock at the read (the ``clock``
        offsets; default: now).
        """
        self.observe(items, now_ns)
        out: list[tuple[SensorState, BioTacBatch]] = []
        for item in items:
            out += self._add(item, host_ns)
        return out

    def resume(self, gap_s: float) -> list[tuple[SensorState, BioTacBatch]]:
        """The device came back after ``gap_s`` away: emit what is pending, count the absence.

        The frames missed meanwhile are counted as lost (by host time: the
        device's own counters restart after a replug), and ``clock`` stamps
        are anchored again.
        """
        out = []
        for st in self.state.values():
            batch = self._flush(st)
            if batch is not None:
                out.append((st, batch))
            st.next_seq = None
            st.last_sample_ns = None
            st.resume_from_ns = st.last_host_ns
            st.last_gap_s = float(gap_s)
        self.clock.reset()
        return out

    def add(self, item: ReadItem, host_ns: int | None = None) -> list[tuple[SensorState, BioTacBatch]]:
        """Take the frames of one BioTac from a read of its own (:meth:`add_read` of one item)."""
        return self.add_read([item], host_ns)

    def _add(self, item: ReadItem, host_ns: int | None = None) -> list[tuple[SensorState, BioTacBatch]]:
        st = self.state[item.chip_select]
        frames = item.frames
        host = time.monotonic_ns() if host_ns is None else int(host_ns)
        stamp = self.stamp(item.chip_select, int(item.device_t_ns[0]))
        seq = int(item.sequence[0])
        out = []
        st.frames_total += len(frames)
        st.counts = st.counts + frames.counts
        if st.resume_from_ns is not None:  # first frames after the device was gone
            missed = max(0, int(round((host - st.resume_from_ns) / self.frame_period_ns)) - 1)
            st.lost_frames += missed
            st.gaps += 1
            st.resumed_gaps += 1
            st.resume_from_ns = None
        elif st.next_seq is not None and seq != st.next_seq:
            if seq > st.next_seq:
                st.lost_frames += seq - st.next_seq
                st.gaps += 1
            batch = self._flush(st)
            if batch is not None:
                out.append((st, batch))
        st.last_host_ns = host
        st.next_seq = seq + len(frames)
        if self.stamp_source == "clock" and st.last_sample_ns is not None \
                and stamp + int(self._pac_off[0]) <= st.last_sample_ns:
            # The clock offset dropped (a read with a smaller delay than any before): this frame would start
            # before the previous one ended.  Dropped and counted; the batch so far ends here.
            self.faults["clock_step_back_frames"] += len(frames)
            batch = self._flush(st)
            return out + ([(st, batch)] if batch is not None else [])
        st.last_sample_ns = stamp + int(self._pac_off[-1])
        if st.first_stamp_ns is None:
            st.first_stamp_ns = stamp
        for k in range(len(frames)):
            if frames.pdc_valid[k]:
                st.recent_pdc.append((stamp, float(frames.pdc[k])))
                st.recent_el.append(np.where(frames.electrodes_valid[k], frames.electrodes[k], np.nan))
                if st.tared and self.track_alpha > 0:
                    self._track_baseline(st, float(frames.pdc[k]))
        if not st.tared and self.tare_on_start_s > 0:
            if stamp - st.first_stamp_ns >= self.tare_on_start_s * 1e9:
                ok, why = self.tare_one(st, self.tare_on_start_s, check_contact=False)
                if ok:
                    self._log("info", f"{st.cfg.sensor_name}: start tare {why}")
                else:
                    self._log("warning", f"{st.cfg.sensor_name}: start tare failed: {why}")
            return out  # nothing is emitted before the start tare
        st.frames.append((seq, stamp, frames))
        if sum(len(f) for _, _, f in st.frames) >= self.batch_frames:
            batch = self._flush(st)
            if batch is not None:
                out.append((st, batch))
        return out

    def _flush(self, st: SensorState) -> BioTacBatch | None:
        if not st.frames:
            return None
        pac_off = self._pac_off
        seq0, _, _ = st.frames[0]
        frame_t = np.array([t for _, t, f in st.frames for _ in range(len(f))], np.int64)
        stamp = int(frame_t[0] + pac_off[0])
        pac = np.concatenate([f.pac for _, _, f in st.frames]).reshape(-1)
        pac_t = (frame_t[:, None] + pac_off[None, :]).reshape(-1)
        el = np.concatenate([f.electrodes for _, _, f in st.frames])
        bad = sum(f.counts.bad for _, _, f in st.frames)
        batch = BioTacBatch(
            stamp_ns=stamp, pac=pac, pac_offset_ns=pac_t - stamp, frame_offset_ns=frame_t - stamp,
            pdc=np.concatenate([f.pdc for _, _, f in st.frames]), tac=np.concatenate([f.tac for _, _, f in st.frames]),
            tdc=np.concatenate([f.tdc for _, _, f in st.frames]), electrodes=el, first_frame_sequence=seq0,
            bad_words=bad)
        st.frames = []
        return batch

    # ------------------------------------------------------------------ tare
    def _track_baseline(self, st: SensorState, pdc: float) -> None:
        """Follow slow PDC drift (temperature) while the finger is clearly not touching.

        A start tare alone lets the baseline drift by tenths of a newton
        within a minute, above the release threshold, so explorations never
        end.  Frames whose tared force is under ``track_band_n`` move the
        baseline towards them; a touch (force above the band) freezes it.
        """
        if abs(pdc - st.tare_pdc) * self.force_n_per_count < self.track_band_n:
            st.tare_pdc += (pdc - st.tare_pdc) * self.track_alpha
            st.tracked_frames += 1

    def force_now(self, st: SensorState) -> float | None:
        """Tared force of the last frames [N] (``None`` before the tare)."""
        if not st.tared or not st.recent_pdc:
            return None
        last = [p for _, p in list(st.recent_pdc)[-10:]]
        return (float(np.mean(last)) - st.tare_pdc) * self.force_n_per_count

    def tare_one(self, st: SensorState, window_s: float, check_contact: bool,
                 force_threshold_n: float = float("inf"), *, rest_percentile: float = 100.0) -> tuple[bool, str]:
        """Set the PDC and electrode baselines to their resting level over the last ``window_s`` of frames.

        The level is :func:`~..core.tare.resting_level` of the frames with a
        readable PDC in the window (the electrodes over the same frames), so a
        span read offline gets the same level from the same samples.

        Parameters
        ----------
        st : SensorState
        window_s : float
            Frames stamped within this long of the newest one [s].
        check_contact : bool
            Refuse while the force of the last frames is at or above ``force_threshold_n``.
        force_threshold_n : float
        rest_percentile : float
            Share of the window known to rest (:func:`~..core.tare.resting_level`): 100
            for ``~/tare`` and the start tare, which take a window without contact.

        Returns
        -------
        (bool, str)
            Whether the sensor was tared, and what was done or why not.  The
            electrodes go untared (``tare_electrodes`` None) when fewer than
            :data:`~..core.tare.MIN_REST_SAMPLES` frames of the window read all of them.
        """
        if check_contact:
            f = self.force_now(st)
            if f is not None and f >= force_threshold_n:
                return False, f"{st.cfg.sensor_name} is in contact ({f:.2f} N >= {force_threshold_n} N)"
        if not st.recent_pdc:
            return False, f"{st.cfg.sensor_name}: no valid PDC samples yet"
        stamps = np.array([t for t, _ in st.recent_pdc], dtype=np.int64)
        take = stamps >= stamps[-1] - window_s * 1e9
        if np.count_nonzero(take) < MIN_REST_SAMPLES:
            return False, (f"{st.cfg.sensor_name}: only {np.count_nonzero(take)} valid PDC samples in the last "
                           f"{window_s} s")
        pdc = np.array([p for _, p in st.recent_pdc])[take]
        el = np.array(st.recent_el)[take].T  # (electrodes, frames), frame for frame with the PDC
        el_readable = np.count_nonzero(np.isfinite(el).all(axis=0)) >= MIN_REST_SAMPLES
        try:
            lvl = resting_level(pdc, el if el_readable else None, rest_percentile=rest_percentile)
        except SignalError as e:
            return False, f"{st.cfg.sensor_name}: {e}"
        st.tare_pdc = float(lvl.reference[0])
        st.tare_electrodes = lvl.channels if el_readable else None
        st.tared = True
        return True, f"PDC baseline {st.tare_pdc:.1f} counts from {lvl.samples} frames"
