"""Skin-cell payloads, CAN layout (python-can virtual bus) and serial framing."""

from __future__ import annotations

import uuid

import can
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tactile_descriptors_ros.codecs.skin import Modality, SkinSample, pack_values, unpack_values
from tactile_descriptors_ros.codecs.skin_can import (
    PROTOCOL_TAG,
    SkinCanDecoder,
    SkinCanEncoder,
    arbitration_id,
    encode_can_message,
    split_arbitration_id,
)
from tactile_descriptors_ros.codecs.skin_serial import SYNC, SkinSerialDecoder, SkinSerialEncoder, encode_skin_frame
from tactile_descriptors_ros.errors import CodecError, FrameError


def test_payloads_hand_computed():
    # x=-1 (0x3FF), y=1, z=-512 (0x200): 0x3FF<<20 | 1<<10 | 0x200 = 0x3FF00600
    assert pack_values(Modality.ACCEL, (-1, 1, -512)) == bytes.fromhex("3ff00600")
    assert unpack_values(Modality.ACCEL, bytes.fromhex("3ff00600")) == (-1, 1, -512)
    # 0xABC<<28 | 0x001<<16 | 0xFFF<<4 = 0xABC001FFF0
    assert pack_values(Modality.FORCE, (0xABC, 1, 0xFFF)) == bytes.fromhex("abc001fff0")
    assert pack_values(Modality.PROXIMITY, (513,)) == b"\x02\x01"
    assert pack_values(Modality.TEMPERATURE, (-2550,)) == (-2550).to_bytes(2, "big", signed=True)


def test_payload_errors():
    with pytest.raises(CodecError):
        unpack_values(Modality.ACCEL, bytes.fromhex("c0000000"))  # must-be-zero bits
    with pytest.raises(CodecError):
        unpack_values(Modality.FORCE, bytes.fromhex("0000000001"))
    with pytest.raises(CodecError):
        unpack_values(Modality.PROXIMITY, b"\xff\xff")  # reserved
    with pytest.raises(FrameError):
        unpack_values(Modality.FORCE, b"\x00")
    with pytest.raises(CodecError):
        unpack_values(9, b"")
    with pytest.raises(CodecError):
        pack_values(Modality.ACCEL, (512, 0, 0))
    with pytest.raises(CodecError):
        pack_values(Modality.FORCE, (1, 2))


_values = {
    Modality.ACCEL: st.tuples(*[st.integers(-512, 511)] * 3),
    Modality.FORCE: st.tuples(*[st.integers(0, 4095)] * 3),
    Modality.PROXIMITY: st.tuples(st.integers(0, 0xFFFE)),
    Modality.TEMPERATURE: st.tuples(st.integers(-32767, 32767)),
}
samples = st.sampled_from(list(Modality)).flatmap(
    lambda m: st.builds(SkinSample, st.integers(0, 0xFFFF), st.just(m), st.integers(0, 255), _values[m]))


@settings(max_examples=150, deadline=None)
@given(samples)
def test_payload_and_can_round_trip(sample):
    assert unpack_values(sample.modality, pack_values(sample.modality, sample.values)) == sample.values
    msg = encode_can_message(sample)
    assert msg.is_extended_id and split_arbitration_id(msg.arbitration_id) == (
        PROTOCOL_TAG, int(sample.modality), sample.cell_id)
    assert SkinCanDecoder().decode(msg) == sample


@settings(max_examples=60, deadline=None)
@given(st.lists(samples, min_size=1, max_size=10), st.integers(1, 16))
def test_serial_round_trip_any_chunking(items, chunk):
    # one frame per (cell, modality) key at most, so the sequence numbers are not duplicates
    unique = list({(s.cell_id, s.modality): s for s in items}.values())
    stream = b"".join(encode_skin_frame(s) for s in unique)
    dec = SkinSerialDecoder()
    got = []
    for i in range(0, len(stream), chunk):
        got += dec.feed(stream[i: i + chunk])
    assert got == unique and dec.stats.errors == 0


def test_arbitration_priority_and_layout():
    assert arbitration_id(0x1234, Modality.FORCE) == (0x15A << 20) | (2 << 16) | 0x1234
    assert arbitration_id(5, Modality.ACCEL) < arbitration_id(5, Modality.FORCE) < arbitration_id(0, Modality.PROXIMITY)
    with pytest.raises(CodecError):
        arbitration_id(70000, Modality.ACCEL)


def test_can_decoder_counts_every_kind_of_bad_frame():
    enc = SkinCanEncoder()
    dec = SkinCanDecoder(known_cell_ids=[1, 2])
    good = [enc.encode(1, Modality.ACCEL, (i, -i, 0)) for i in range(5)]
    msgs = [good[0], good[1], good[1], good[3], good[2], good[4],                       # dup, reorder
            can.Message(arbitration_id=0x123, is_extended_id=False, data=b"\x00"),       # foreign
            can.Message(arbitration_id=(0x100 << 20) | (1 << 16) | 1, data=b"\x00" * 5),  # other tag
            can.Message(arbitration_id=(PROTOCOL_TAG << 20) | (9 << 16) | 1, data=b"\x00" * 3),
            can.Message(arbitration_id=arbitration_id(1, Modality.FORCE), data=b"\x00" * 5),
            can.Message(arbitration_id=arbitration_id(2, Modality.ACCEL), data=b"\x00\xc0\x00\x00\x00"),
            enc.encode(77, Modality.FORCE, (1, 2, 3)), enc.encode(77, Modality.FORCE, (1, 2, 3)),
            can.Message(arbitration_id=arbitration_id(1, Modality.FORCE), is_remote_frame=True, dlc=6),
            can.Message(is_error_frame=True)]
    got = dec.decode_many(msgs)
    assert [(s.cell_id, s.sequence, s.values) for s in got] == [(1, i, (i, -i, 0)) for i in (0, 1, 3, 2, 4)]
    s = dec.stats
    assert (s.duplicates, s.out_of_order, s.lost_frames, s.foreign_frames, s.unknown_modality, s.bad_length,
            s.bad_payload, s.unknown_cells, s.remote_or_error_frames) == (1, 1, 0, 2, 1, 1, 1, 2, 2)
    assert dict(s.unknown_cell_ids) == {77: 2}
    assert s.frames == len(msgs) and s.samples == 5


def test_can_drop_is_a_counted_gap():
    enc = SkinCanEncoder()
    msgs = [enc.encode(3, Modality.FORCE, (0, 0, i)) for i in range(300)]  # sequence wraps at 256
    dec = SkinCanDecoder()
    got = dec.decode_many(m for i, m in enumerate(msgs) if i not in (10, 11, 255, 256))
    assert len(got) == 296 and dec.stats.lost_frames == 4 and dec.stats.sequence_gaps == 2


def test_can_over_python_can_virtual_bus():
    from tactile_descriptors_ros.transports import create_transport

    channel = f"tdr-{uuid.uuid4().hex}"
    enc = SkinCanEncoder()
    sent = [enc.next_sample(11, Modality.ACCEL, (i, 0, -i)) for i in range(20)]
    dec = SkinCanDecoder(known_cell_ids=[11])
    with create_transport("can", interface="virtual", channel=channel) as tx, \
            create_transport("can", interface="virtual", channel=channel) as rx:
        for s in sent:
            tx.send(encode_can_message(s))
        got = []
        while (msg := rx.recv(timeout_s=0.2)) is not None:
            sample = dec.decode(msg)
            if sample is not None:
                got.append(sample)
    assert [(g.cell_id, g.sequence, g.values) for g in got] == [(s.cell_id, s.sequence, s.values) for s in sent]
    assert all(g.stamp_ns and g.stamp_ns > 0 for g in got)
    assert dec.stats.errors == 0


def test_skin_serial_counts_rejects_and_resyncs():
    enc = SkinSerialEncoder()
    a = enc.encode(1, Modality.FORCE, (1, 2, 3))
    b = enc.encode(1, Modality.FORCE, (4, 5, 6))
    c = enc.encode(2, Modality.PROXIMITY, (99,))
    u = enc.encode(500, Modality.TEMPERATURE, (2100,))
    dec = SkinSerialDecoder(known_cell_ids=[1, 2])
    broken = bytearray(b)
    broken[9] ^= 0x01
    got = dec.feed(b"\xc3" + a + bytes(broken) + b"xyz" + u + c + a)
    assert [(s.cell_id, s.values) for s in got] == [(1, (1, 2, 3)), (2, (99,))]
    st_ = dec.stats
    assert st_.crc_errors == 1 and st_.duplicates == 1 and st_.bad_payloads == 1
    assert dec.reject_reasons == {"unknown_cell": 1} and dict(dec.unknown_cell_ids) == {500: 1}
    assert st_.garbage_bytes >= 4
    assert a.startswith(SYNC)


def test_can_example_from_the_docs():
    msg = encode_can_message(SkinSample(0x1234, Modality.FORCE, 5, (0xABC, 1, 0xFFF)))
    assert msg.arbitration_id == 0x15A21234 and bytes(msg.data) == bytes.fromhex("05abc001fff0")
