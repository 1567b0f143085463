"""Bridge serial framing: CRC check value, worked example, resync, counted faults, loop:// transport."""

from __future__ import annotations

import zlib

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tactile_descriptors_ros.codecs import biotac_spi as spi
from tactile_descriptors_ros.codecs.bridge_serial import (
    SYNC,
    BridgeDecoder,
    BridgeEncoder,
    BridgeFrame,
    BridgeFrameType,
    encode_bridge_frame,
)
from tactile_descriptors_ros.codecs.framing import CRC_NAME, SequenceEvent, SequenceTracker, crc32
from tactile_descriptors_ros.errors import CodecError, ConfigError

#: The worked example of docs/protocols.md: chip select 2, sequence 7, t_us 1000,
#: payload = one reply word of value 0x5A5.
EXAMPLE = bytes.fromhex("b14e" "01" "02" "0007" "000003e8" "0002" "5b29") + bytes.fromhex("5a346825")


def test_crc_is_crc32_iso_hdlc_with_its_check_value():
    assert CRC_NAME == "CRC-32/ISO-HDLC"
    assert crc32(b"123456789") == 0xCBF43926
    assert crc32(b"") == 0


def test_worked_example_from_the_docs():
    frame = BridgeFrame(BridgeFrameType.SAMPLE, 2, 7, 1000, spi.encode_word(0x5A5))
    wire = encode_bridge_frame(frame)
    assert wire[:-4] == EXAMPLE[:-4]
    assert wire[-4:] == (zlib.crc32(wire[2:-4]) & 0xFFFFFFFF).to_bytes(4, "big")
    assert wire == EXAMPLE
    assert BridgeDecoder().feed(wire) == [frame]


def test_sync_bytes_never_occur_in_valid_biotac_bytes():
    for b in SYNC:
        assert bin(b).count("1") % 2 == 0


def _frames(n, cs=0, start=0):
    enc = BridgeEncoder()
    out = []
    for i in range(n):
        payload = spi.encode_words([(i * 37 + k) % 4096 for k in range(44)])
        out.append(enc.encode(cs, payload, t_us=i * 10_000))
    return out


def test_stream_in_pieces_and_resync_after_garbage():
    wires = _frames(5)
    stream = b"\x00\xb1\xff" + wires[0] + b"garbage\xb1" + wires[1] + wires[2] + bytes(range(50)) + b"".join(wires[3:])
    dec = BridgeDecoder()
    got = []
    for i in range(0, len(stream), 7):
        got += dec.feed(stream[i: i + 7])
    assert [f.sequence for f in got] == [0, 1, 2, 3, 4]
    assert dec.stats.frames == 5 and dec.stats.crc_errors == 0 and dec.stats.lost_frames == 0
    assert dec.stats.garbage_bytes == 3 + 8 + 50
    assert dec.stats.resyncs == 3


def test_crc_error_truncation_gap_and_duplicate_are_counted():
    w = _frames(6)
    bad = bytearray(w[1])
    bad[20] ^= 0x04
    stream = w[0] + bytes(bad) + w[2][:30] + w[3] + w[3] + w[5]
    dec = BridgeDecoder()
    got = dec.feed(stream) + dec.finish()
    assert [f.sequence for f in got] == [0, 3, 5]
    s = dec.stats
    assert s.crc_errors == 1
    assert s.truncated == 1
    assert s.duplicates == 1
    assert s.lost_frames == 3 and s.sequence_gaps == 2  # 1, 2 and 4 never arrived intact


def test_impossible_header_and_end_of_stream():
    body = bytes.fromhex("01" "07" "0000" "00000000" "0000")  # chip select 7
    dec = BridgeDecoder()
    w = _frames(2)
    got = dec.feed(SYNC + body + crc32(body).to_bytes(4, "big") + w[0] + w[1][:15])
    assert [f.sequence for f in got] == [0]
    assert dec.stats.bad_headers == 1
    assert dec.pending_bytes == 15
    dec.finish()
    assert dec.stats.truncated == 1 and dec.pending_bytes == 0


def test_false_sync_at_end_does_not_hide_frames():
    w = _frames(2)
    fake = SYNC + bytes.fromhex("01 00 0000 00000000 0400")  # promises 1024 bytes
    dec = BridgeDecoder()
    got = dec.feed(fake + w[0] + w[1])
    assert got == []  # still waiting for the promised bytes
    got = dec.finish()
    assert [f.sequence for f in got] == [0, 1]


def test_encoder_rejects_bad_fields():
    with pytest.raises(CodecError):
        encode_bridge_frame(BridgeFrame(BridgeFrameType.SAMPLE, 5, 0, 0, b""))
    with pytest.raises(CodecError):
        encode_bridge_frame(BridgeFrame(BridgeFrameType.SAMPLE, 0, 0, 0, bytes(1025)))


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 4), st.binary(max_size=120), st.integers(0, 2**32 - 1),
                          st.sampled_from(list(BridgeFrameType))), min_size=1, max_size=12),
       st.integers(1, 64), st.binary(max_size=20))
def test_round_trip_any_frames_any_chunking(frames, chunk, junk):
    enc = BridgeEncoder()
    wires = [enc.encode(cs, payload, t, kind) for cs, payload, t, kind in frames]
    stream = junk + b"".join(wires)
    dec = BridgeDecoder()
    got = []
    for i in range(0, len(stream), chunk):
        got += dec.feed(stream[i: i + chunk])
    got += dec.finish()
    assert [(f.chip_select, f.payload, f.t_us, f.kind) for f in got] == [tuple(f) for f in frames]
    assert dec.stats.crc_errors == 0 and dec.stats.lost_frames == 0 and dec.stats.duplicates == 0


def test_sequence_tracker_wraps_and_detects():
    t = SequenceTracker(256, window=16)
    assert t.update("a", 254) is SequenceEvent.FIRST
    assert t.update("a", 255) is SequenceEvent.IN_ORDER
    assert t.update("a", 0) is SequenceEvent.IN_ORDER      # wrap
    assert t.update("a", 3) is SequenceEvent.GAP            # 1, 2 lost
    assert t.lost == 2 and t.gaps == 1
    assert t.update("a", 1) is SequenceEvent.LATE           # fills a hole
    assert t.lost == 1
    assert t.update("a", 3) is SequenceEvent.DUPLICATE
    assert t.update("a", 100) is SequenceEvent.GAP
    assert t.update("a", 50) is SequenceEvent.RESET         # far back: sender restarted
    assert t.resets == 1
    assert t.update("b", 7) is SequenceEvent.FIRST           # keys are independent
    with pytest.raises(ConfigError):
        SequenceTracker(16, window=8)


def test_bridge_over_serial_loop_url():
    from tactile_descriptors_ros.transports import create_transport

    wires = _frames(3, cs=4)
    dec = BridgeDecoder()
    with create_transport("serial", port="loop://", timeout_s=0.05) as port:
        port.write(b"\x55" + b"".join(wires))
        got = []
        for _ in range(50):
            data = port.read(64)
            if not data:
                break
            got += dec.feed(data)
    assert [(f.chip_select, f.sequence) for f in got] == [(4, 0), (4, 1), (4, 2)]
    frames = spi.BiotacFrameDecoder("default", sensors=(4,)).decode_many(4, b"".join(f.payload for f in got))
    assert frames.counts.bad == 0 and frames.pac[1, 0] == (1 * 37 + 1) % 4096
