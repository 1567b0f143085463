"""The stream layer without ROS: skin cells that go quiet, bridge payloads of the wrong pattern."""

from __future__ import annotations

from collections import Counter

import numpy as np
import pytest

from tactile_descriptors_ros.codecs import biotac_spi as spi
from tactile_descriptors_ros.codecs.bridge_serial import BridgeEncoder
from tactile_descriptors_ros.codecs.skin import NO_STAMP, Modality, SkinSampleBatch
from tactile_descriptors_ros.codecs.skin_can import SkinCanDecoder, encode_can_frames
from tactile_descriptors_ros.errors import FrameError
from tactile_descriptors_ros.streams.biotac import BiotacStream, BridgeFrameSource, SensorConfig
from tactile_descriptors_ros.streams.skin import SkinStream
from tactile_descriptors_ros.transports.loopback import LoopbackTransport

MS = 1_000_000
T0 = 1_700_000_000 * 10**9  # bus times in the epoch clock, as python-can gives them
CELL = 7
SILENT_MS = [(300, 500), (700, 1000)]  # 200 ms, then 300 ms without a frame
END_MS = 1300


def _quiet_cell_samples() -> tuple[SkinSampleBatch, np.ndarray]:
    """One cell, accelerometer at 1 kHz and force at 250 Hz, numbered as the firmware does (8-bit,
    wrapping), silent in SILENT_MS; returns the samples (bus time = true sample time) and each one's ms."""
    rows = []
    for ms in range(END_MS):
        if any(a <= ms < b for a, b in SILENT_MS):
            continue
        rows.append((Modality.ACCEL, ms % 256, (ms % 50 - 25, 3, -4), ms))
        if ms % 4 == 0:
            rows.append((Modality.FORCE, (ms // 4) % 256, (100, 110, 120), ms))
    n = len(rows)
    vals = np.array([r[2] for r in rows], dtype=np.int64)
    ms = np.array([r[3] for r in rows], dtype=np.int64)
    batch = SkinSampleBatch(np.full(n, CELL, np.int64), np.array([int(r[0]) for r in rows], np.int64),
                            np.array([r[1] for r in rows], np.int64), vals, T0 + ms * MS)
    return batch, ms


def _expected_lost() -> int:
    accel = sum(b - a for a, b in SILENT_MS)
    force = sum(len([m for m in range(a, b) if m % 4 == 0]) for a, b in SILENT_MS)
    return accel + force


@pytest.mark.parametrize("bus_times", [True, False], ids=["bus-times", "arrival-times"])
def test_skin_cell_silent_200_then_300_ms_keeps_its_stamps_and_counts_the_gaps(bus_times):
    """Sequence numbers wrap every 256 ms at 1 kHz: a 200 ms silence looks like 56 frames back and a
    300 ms one like 44 forward.  Stamps must stay the true sample times (one constant anchor offset,
    never 256 or 512 ms early, never a step back) and the lost frames must be those of the silences."""
    batch, ms = _quiet_cell_samples()
    if not bus_times:  # an adapter without times: the stream times each read by its arrival
        batch = SkinSampleBatch(batch.cell_id, batch.modality, batch.sequence, batch.values,
                                np.full(len(batch), NO_STAMP, np.int64))
    frames = encode_can_frames(batch)
    decoder = SkinCanDecoder(known_cell_ids={CELL})
    now = {"ns": 0}
    stream = SkinStream({CELL: ("left_hand", "cell7")}, 1000.0, 250.0, 0.05, "clock", 0.0, 0.0,
                        lambda: now["ns"], Counter())
    out = []
    for read_ms in range(0, END_MS + 10, 10):  # the reader takes what arrived in each 10 ms
        sel = (ms >= read_ms - 10) & (ms < read_ms)
        if not sel.any():
            continue
        arrival = T0 + read_ms * MS + 2 * MS
        now["ns"] = arrival
        got = decoder.decode_frames(frames[sel], None if bus_times else arrival)
        out += stream.add(got, arrival)
    acc_t = np.concatenate([f.stamp_ns + f.accel_offset_ns for _, f in out])
    true_t = T0 + ms[batch.modality == Modality.ACCEL] * MS
    true_t = true_t[:acc_t.size]
    assert acc_t.size > 700
    offset = acc_t - true_t
    if bus_times:
        assert np.all(offset == offset[0]), np.unique(offset)[:5]  # one anchor, no 256/512 ms shift
        assert 0 <= offset[0] <= 12 * MS
    else:  # the read's arrival times the samples to within the read period: still no wrap
        assert np.all(np.abs(offset - offset[0]) < 20 * MS), np.unique(offset // MS)
    assert np.all(np.diff(acc_t) > 0)  # never a step back
    lost = _expected_lost()
    assert decoder.stats.lost_frames == lost and decoder.stats.sequence_resets == 0
    assert stream.cells[CELL].lost == lost
    assert decoder.stats.sequence_gaps == 4  # two silences in two modalities


def _bridge_bytes(pattern: spi.FramePattern, n: int, enc: BridgeEncoder, cs: int = 0) -> bytes:
    vals = {"PAC": [2000] * pattern.pac_count, "electrodes": [3000] * pattern.electrode_count,
            "PDC": 1500, "TAC": 2200, "TDC": 2600}
    return b"".join(enc.encode(cs, spi.encode_frame(pattern, vals), t_us=k * 10_000) for k in range(n))


def test_decode_many_refuses_a_biotac_sp_frame_read_with_the_default_pattern():
    sp = spi.FramePattern.parse("biotac_sp")
    vals = {"PAC": [2000] * sp.pac_count, "electrodes": [3000] * sp.electrode_count,
            "PDC": 1500, "TAC": 2200, "TDC": 2600}
    with pytest.raises(FrameError):
        spi.BiotacFrameDecoder(spi.FramePattern.parse("default"), [0]).decode_many(0, spi.encode_frame(sp, vals))
    # two whole frames back to back still decode; one frame where at most one may come too
    d = spi.FramePattern.parse("default")
    one = spi.encode_frame(d, {"PAC": [1] * d.pac_count, "electrodes": [2] * 19, "PDC": 3, "TAC": 4, "TDC": 5})
    assert len(spi.BiotacFrameDecoder(d, [0]).decode_many(0, one + one)) == 2
    with pytest.raises(FrameError):
        spi.BiotacFrameDecoder(d, [0]).decode_many(0, one + one, max_frames=1)


def test_bridge_payload_of_another_pattern_is_a_counted_error_never_frames():
    default = spi.FramePattern.parse("default")
    port = LoopbackTransport()
    port.open()
    source = BridgeFrameSource(port, default, [0], spi.BiotacFrameDecoder(default, [0]), read_timeout_s=0.0,
                               frame_period_ns=10 * MS)
    enc = BridgeEncoder()
    port.write(_bridge_bytes(spi.FramePattern.parse("biotac_sp"), 20, enc))
    items = source.read()
    assert items == [] and source.decode_errors == 20
    assert "does not match" in source.last_decode_error
    port.write(_bridge_bytes(default, 3, enc))
    assert [len(i.frames) for i in source.read()] == [1, 1, 1]


def test_bridge_sequence_across_a_silence_longer_than_half_a_wrap():
    """16-bit numbers at 100 Hz wrap every 655 s: a bridge silent for 400 s (its clock tells) is a gap
    of 40,000 frames, not a step back."""
    default = spi.FramePattern.parse("default")
    port = LoopbackTransport()
    port.open()
    source = BridgeFrameSource(port, default, [0], spi.BiotacFrameDecoder(default, [0]), read_timeout_s=0.0,
                               frame_period_ns=10 * MS)
    enc = BridgeEncoder()
    vals = {"PAC": [2000] * default.pac_count, "electrodes": [3000] * 19, "PDC": 1500, "TAC": 2200, "TDC": 2600}
    payload = spi.encode_frame(default, vals)
    from tactile_descriptors_ros.codecs.bridge_serial import BridgeFrame, BridgeFrameType, encode_bridge_frame

    port.write(enc.encode(0, payload, t_us=0))
    first = source.read()[0]
    gap = 40_000
    port.write(encode_bridge_frame(BridgeFrame(BridgeFrameType.SAMPLE, 0, (1 + gap) % 65536, (1 + gap) * 10_000,
                                               payload)))
    later = source.read()[0]
    assert int(later.sequence[0]) - int(first.sequence[0]) == 1 + gap
    stream = BiotacStream({0: SensorConfig(0, "bt", "index", "bt")}, default, 4400.0, 10, "device", 0.0, 0.0,
                          0.0, 0.0, 0.01, lambda: 0, Counter())
    stream.add(first)
    stream.add(later)
    assert stream.state[0].lost_frames == gap and stream.state[0].gaps == 1
