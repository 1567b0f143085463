"""Device clock -> host clock: stamps are acquisition times, never later than the read that returned them.

Every test knows the true offset between the simulated device clock and the
host clock and the transport delay of every sample, so the error of a stamp
is measured, not guessed.
"""

from __future__ import annotations

from collections import Counter

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tactile_descriptors_ros.codecs import biotac_spi as spi
from tactile_descriptors_ros.codecs.bridge_serial import BridgeEncoder
from tactile_descriptors_ros.codecs.skin import Modality, SkinSampleBatch
from tactile_descriptors_ros.codecs.skin_can import SkinCanDecoder, encode_can_frames
from tactile_descriptors_ros.streams.biotac import BiotacStream, BridgeFrameSource, SensorConfig
from tactile_descriptors_ros.streams.clock import DeviceClock
from tactile_descriptors_ros.streams.skin import SkinStream
from tactile_descriptors_ros.transports.loopback import LoopbackTransport

MS = 1_000_000
HOST0 = 1_700_000_000 * 10**9  # host (node) clock: epoch nanoseconds
OFFSET = HOST0 - 123_456_789_012  # host minus device clock at device time 0


def _delays(rng: np.random.Generator, n: int, floor_ns: int = 200_000, mean_ns: int = 3 * MS) -> np.ndarray:
    """Transport delays: a floor (wire, adapter) plus exponential jitter (scheduling, a busy machine)."""
    return floor_ns + rng.exponential(mean_ns, n).astype(np.int64)


def _next_read(rng: np.random.Generator, host: int, next_arrival: int) -> int:
    """When the reader reads next: it blocks until data arrives, but is busy 0-2 ms after each read
    and, one read in ten, starved for 5-50 ms (a loaded machine)."""
    busy = int(rng.integers(5, 50)) * MS if rng.random() < 0.1 else int(rng.integers(0, 2 * MS))
    return max(host + busy, next_arrival)


def test_the_estimate_converges_to_the_offset_plus_the_least_delay_and_follows_drift():
    """Reads every 10 ms of a device clock 80 ppm slow, delays 0.2 ms + exponential(3 ms): after the
    first second every estimate is within 1 ms of the true offset plus the 0.2 ms floor."""
    rng = np.random.default_rng(1)
    clock = DeviceClock(1)
    n = 6000  # 60 s
    acq_host = HOST0 + np.arange(n, dtype=np.int64) * 10 * MS  # true acquisition, host clock
    dev = ((acq_host - OFFSET) * (1 - 80e-6)).astype(np.int64)  # the device clock runs 80 ppm slow
    host = acq_host + _delays(rng, n)
    err = []
    for i in range(n):
        clock.observe(np.array([0]), dev[i:i + 1], int(host[i]))
        stamp = int(clock.to_host(0, dev[i]))
        assert stamp <= host[i]
        err.append(stamp - acq_host[i])
    err = np.array(err[100:])
    assert np.all(err >= 0)  # an estimate is never below the true offset (delays are never negative)
    assert err.max() < 1 * MS, err.max()
    assert clock.resyncs == 0


def test_a_backlog_read_at_the_first_read_is_stamped_when_it_was_taken_not_now():
    """The first read after configure returns 0.6 s of frames buffered meanwhile: only the newest
    sample is close to the read time, and the oldest must keep its own time (not the read's)."""
    clock = DeviceClock(1)
    dev = np.arange(600, dtype=np.int64) * MS  # 600 frames, one per ms
    host_read = OFFSET + int(dev[-1]) + 300_000  # read 0.3 ms after the newest was taken
    clock.observe(np.array([0]), dev[-1:], host_read)
    stamps = clock.to_host(np.zeros(600, np.int64), dev)
    assert np.all(stamps <= host_read)
    assert np.all(np.abs(stamps - (OFFSET + dev)) <= 300_000)
    assert host_read - stamps[0] == 599 * MS  # the oldest frame is 599 ms older than the newest, as it was


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 50 * MS), st.integers(0, 5_000 * MS)), min_size=1, max_size=60),
       st.integers(-10**15, 10**15))
def test_no_stamp_is_later_than_the_read_that_returned_it(reads, offset):
    """Whatever the delays and the gaps between reads (the device clock advancing by any amount,
    delays of any size), every sample of a read is stamped at or before the read's host time."""
    clock = DeviceClock(1)
    dev_t = 0
    for gap, delay in reads:
        dev_t += gap + 1
        host = offset + dev_t + delay
        clock.observe(np.array([0]), np.array([dev_t]), host)
        samples = np.array([dev_t - 5 * MS, dev_t - 1, dev_t], dtype=np.int64)
        assert np.all(clock.to_host(np.zeros(3, np.int64), samples) <= host)


def test_a_device_clock_that_steps_back_is_reanchored_and_counted():
    clock = DeviceClock(2, jump_ns=1_000 * MS)
    clock.observe(np.array([0, 1]), np.array([50_000 * MS, 50_000 * MS]), HOST0)
    # key 0's device restarted its clock at 0; key 1 runs on
    clock.observe(np.array([0, 1]), np.array([10 * MS, 50_010 * MS]), HOST0 + 10 * MS + 200_000)
    assert clock.resyncs == 1
    assert int(clock.to_host(0, 10 * MS)) == HOST0 + 10 * MS + 200_000
    assert int(clock.to_host(1, 50_010 * MS)) == HOST0 + 10 * MS + 5_000  # least delay 0, plus 10 ms of drift allowance


def test_a_device_clock_that_paused_is_reanchored_after_the_confirmation_time_not_at_a_backlog():
    """A backlog (the driver starved for 3 s) lifts the observations for less than the confirmation
    time and changes nothing; a frame clock that paused for 8 s (nobody polled the SPI bus) keeps
    them 8 s up for good and is re-anchored once, after the confirmation time."""
    clock = DeviceClock(1, jump_ns=1_000 * MS, confirm_ns=5_000 * MS)
    dev = 0
    host = HOST0
    for _ in range(100):  # 1 s of reads, delay 0.5 ms
        dev += 10 * MS
        host = OFFSET + dev + MS // 2
        clock.observe(np.array([0]), np.array([dev]), host)
    base = int(clock.offset_ns[0])
    for k in range(300):  # 3 s starved: the reads return frames up to 3 s old
        dev += 10 * MS
        clock.observe(np.array([0]), np.array([dev]), OFFSET + dev + MS // 2 + (3_000 - 10 * k) * MS)
    assert clock.resyncs == 0 and int(clock.offset_ns[0]) - base <= 3 * MS // 2  # only the drift allowance
    for _ in range(700):  # paused 8 s, then on again: every observation 8 s up
        dev += 10 * MS
        clock.observe(np.array([0]), np.array([dev]), OFFSET + dev + 8_000 * MS + MS // 2)
    assert clock.resyncs == 1
    assert abs(int(clock.offset_ns[0]) - (OFFSET + 8_000 * MS + MS // 2)) < MS


# ------------------------------------------------------------------ BioTac bridge


def _bridge_bytes(pattern: spi.FramePattern, frames: range, enc: BridgeEncoder, t0_us: int) -> bytes:
    vals = {"PAC": [2000] * pattern.pac_count, "electrodes": [3000] * pattern.electrode_count,
            "PDC": 1500, "TAC": 2200, "TDC": 2600}
    payload = spi.encode_frame(pattern, vals)
    return b"".join(enc.encode(0, payload, t_us=(t0_us + k * 10_000) & 0xFFFFFFFF) for k in frames)


@pytest.mark.parametrize("after", ["start", "replug", "reconfigure"])
def test_biotac_bridge_stamps_are_acquisition_times_within_a_millisecond(after):
    """A bridge whose clock is OFFSET behind the host's; frames reach the driver 0.2 ms + exponential
    (3 ms) after their last word, read when they arrive unless the reader is busy (``_next_read``),
    the first read after a backlog of 0.6 s (configure to activate).  Every stamp <= its read's host time; after the first second,
    every PAC stamp within 1 ms of its true time: from a fresh start, after a replug (the bridge clock
    restarts elsewhere) and after a reconfigure (a new stream)."""
    pattern = spi.FramePattern.parse("default")
    period_ns = 10 * MS
    pac_off = pattern.pac_offsets_ns(4400.0)
    done_ns = int(pattern.slot_offsets_ns(4400.0)[-1])
    rng = np.random.default_rng(7)
    now = {"ns": 0}

    def new_stream() -> BiotacStream:
        return BiotacStream({0: SensorConfig(0, "bt", "index", "bt")}, pattern, 4400.0, 10, "clock", 1.0, 0.0,
                            0.0, 0.0, 0.01, lambda: now["ns"], Counter())

    def run(stream: BiotacStream, t0_us: int, offset: int, first_host: int, n_frames: int) -> tuple[list, int]:
        """Frames 0.. of a bridge clock starting at t0_us; returns (stamp errors after 1 s, last host)."""
        port = LoopbackTransport()
        port.open()
        source = BridgeFrameSource(port, pattern, [0], spi.BiotacFrameDecoder(pattern, [0]), read_timeout_s=0.0,
                                   frame_period_ns=period_ns, host_clock_ns=lambda: now["ns"])
        enc = BridgeEncoder()
        dev_start = t0_us * 1000 + np.arange(n_frames, dtype=np.int64) * period_ns  # device time of each frame
        arrive = offset + dev_start + done_ns + _delays(rng, n_frames)
        arrive = np.maximum.accumulate(arrive)  # a serial line keeps the order
        host = first_host
        k = 0
        errors = []
        while k < n_frames:
            host = _next_read(rng, host, int(arrive[k]))
            j = int(np.searchsorted(arrive, host, side="right"))
            port.write(_bridge_bytes(pattern, range(k, j), enc, t0_us))
            now["ns"] = host
            items = source.read()
            for _, batch in stream.add_read(items, host):
                pac_t = batch.stamp_ns + batch.pac_offset_ns
                assert pac_t.max() <= host
                first = int(batch.first_frame_sequence)  # the encoder numbers this run's frames from 0
                truth = (offset + dev_start[first:first + batch.frame_count, None] + pac_off[None, :]).ravel()
                if dev_start[first] - dev_start[0] >= 1_000 * MS:
                    errors.append(np.abs(pac_t - truth).max())
            k = j
        return errors, host

    stream = new_stream()
    backlog = 600 * MS  # frames buffered between configure and the first read
    errors, host = run(stream, 5_000_000, OFFSET, OFFSET + 5_000_000_000 + backlog, 400)
    if after == "replug":  # the bridge is back 0.5 s later, its clock restarted at 77 ms
        stream.resume(0.5)
        offset = host + 500 * MS - 77_000_000
        errors, host = run(stream, 77_000, offset, offset + 77_000_000 + backlog, 400)
    elif after == "reconfigure":  # a new stream on the same bridge, 0.2 s later
        stream = new_stream()
        offset = host + 200 * MS - 2_000_000_000
        errors, host = run(stream, 2_000_000, offset, offset + 2_000_000_000 + backlog, 400)
    assert len(errors) > 10
    assert max(errors) < 1 * MS, max(errors)


# ------------------------------------------------------------------ skin cells

CELLS = (3, 7)


def _skin_samples(n_ms: int) -> tuple[SkinSampleBatch, np.ndarray]:
    """Two cells, accelerometer 1 kHz and force 250 Hz, for n_ms; returns samples and device times [ns]."""
    rows = []
    for ms in range(n_ms):
        for c in CELLS:
            rows.append((c, Modality.ACCEL, ms % 256, (ms % 50 - 25, 3, -4), ms))
            if ms % 4 == 0:
                rows.append((c, Modality.FORCE, (ms // 4) % 256, (100, 110, 120), ms))
    n = len(rows)
    batch = SkinSampleBatch(np.array([r[0] for r in rows], np.int64), np.array([int(r[1]) for r in rows], np.int64),
                            np.array([r[2] for r in rows], np.int64), np.array([r[3] for r in rows], np.int64),
                            np.zeros(n, np.int64))
    return batch, np.array([r[4] for r in rows], np.int64) * MS


@pytest.mark.parametrize("after", ["start", "replug"])
def test_skin_clock_stamps_are_acquisition_times_within_a_millisecond(after):
    """Each cell's clock (sequence numbers times the period) runs from an unknown origin, each cell with
    its own offset to the host clock; samples arrive in bus order 0.2 ms + exponential(0.5 ms) after
    acquisition and are read as ``_next_read`` says, the first read after a 0.4 s backlog (or, for ``replug``, the device gone
    and back half-way).  Every stamp <= its read's host time; after the first second every
    accelerometer and force stamp within 1 ms of its true time."""
    rng = np.random.default_rng(3)
    n_ms = 3000
    batch, dev_ns = _skin_samples(n_ms)
    cell_offset = {3: HOST0 + 11 * MS, 7: HOST0 + 17 * MS}  # acquisition on the host clock: device + offset
    true_t = dev_ns + np.array([cell_offset[int(c)] for c in batch.cell_id])
    order = np.argsort(true_t, kind="stable")  # the bus carries them in the order they were taken
    batch, dev_ns, true_t = batch.take(order), dev_ns[order], true_t[order]
    frames = encode_can_frames(SkinSampleBatch(batch.cell_id, batch.modality, batch.sequence, batch.values,
                                               np.full(len(batch), -1, np.int64)))
    # a CAN adapter delivers in bus order, 0.2 ms + exponential(0.5 ms) after the frame (the reader's
    # scheduling adds its own jitter, _next_read)
    arrive = np.maximum.accumulate(true_t + _delays(rng, len(batch), mean_ns=MS // 2))
    now = {"ns": 0}
    decoder = SkinCanDecoder(known_cell_ids=set(CELLS))
    stream = SkinStream({c: ("hand", f"cell{c}") for c in CELLS}, 1000.0, 250.0, 0.01, "clock", 1.0, 0.0,
                        lambda: now["ns"], Counter())
    host = int(true_t[0]) + (400 * MS if after == "start" else 0)
    k = 0
    stamps: dict[tuple[int, str], list[np.ndarray]] = {}
    replugged = False
    while k < len(batch):
        host = _next_read(rng, host, int(arrive[k]))
        j = int(np.searchsorted(arrive, host, side="right"))
        if after == "replug" and not replugged and dev_ns[k] >= 1_500 * MS:
            stream.resume()
            replugged = True
        now["ns"] = host
        for cell, frame in stream.add(decoder.decode_frames(frames[k:j], host), host):
            acc = frame.stamp_ns + frame.accel_offset_ns
            force = frame.stamp_ns + frame.force_offset_ns
            assert acc.max() <= host and (not force.size or force.max() <= host)
            stamps.setdefault((cell.cell_id, "accel"), []).append(acc)
            stamps.setdefault((cell.cell_id, "force"), []).append(force)
        k = j
    for c in CELLS:  # nothing is lost: the k-th sample of a cell and modality is its k-th true sample
        for mod, period in (("accel", 1), ("force", 4)):
            got = np.concatenate(stamps[(c, mod)])
            truth = cell_offset[c] + np.arange(got.size, dtype=np.int64) * period * MS
            late = truth >= cell_offset[c] + 1_000 * MS
            if after == "replug":  # and the second after the replug (the read it happened in holds earlier samples)
                late &= (truth < cell_offset[c] + 1_450 * MS) | (truth >= cell_offset[c] + 2_500 * MS)
            err = got[late] - truth[late]
            assert err.size > 100 and np.all(err >= 0), (c, mod, err.min())
            assert err.max() < 1 * MS, (c, mod, err.max())
