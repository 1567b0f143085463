"""A body part's SkinPartFrames read from its CDR bytes (codecs/cdr.py) against rclpy's own deserialisation."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

pytestmark = pytest.mark.ros

#: The message's array fields and their element types.
_ARRAYS = {"cell_ids": np.uint32, "sequence": np.uint32, "accel_count": np.uint32, "force_count": np.uint32,
           "temperature_c": np.float64, "force_tare_counts": np.float64, "bad_frames": np.uint32,
           "accel_x": np.int16, "accel_y": np.int16, "accel_z": np.int16, "accel_offset_ns": np.int64,
           "force": np.uint16, "force_offset_ns": np.int64, "proximity": np.uint16}
_FLOATS = ("accel_mps2_per_count", "force_n_per_count", "proximity_per_count")


@pytest.fixture(scope="module")
def cdr():
    from tactile_descriptors_ros.codecs import cdr

    if not cdr.load_compiled():
        pytest.skip("no compiled backend")
    return cdr


def _values(data, dtype, n):
    """``n`` values of ``dtype`` over its whole range (floats: any bits but a few NaN payloads' signs)."""
    info = np.iinfo(dtype) if np.issubdtype(dtype, np.integer) else None
    if info is None:
        return np.array(data.draw(st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=n, max_size=n)),
                        dtype=dtype)
    return np.array(data.draw(st.lists(st.integers(int(info.min), int(info.max)), min_size=n, max_size=n)),
                    dtype=dtype)


def _message(data):
    """A SkinPartFrames of any lengths (each array its own, 0 included: CDR aligns only non-empty arrays),
    values, stamp and text; not consistent as frames, which reading does not check."""
    import array

    from tactile_descriptors_msgs.msg import SkinPartFrames

    msg = SkinPartFrames()
    msg.header.stamp.sec = data.draw(st.integers(-2**31, 2**31 - 1))
    msg.header.stamp.nanosec = data.draw(st.integers(0, 999_999_999))
    text = st.text(st.characters(blacklist_categories=("Cs",), blacklist_characters="\0"), max_size=12)
    msg.header.frame_id = data.draw(text)
    msg.body_part = data.draw(text)
    codes = {np.uint32: "I", np.float64: "d", np.int16: "h", np.int64: "q", np.uint16: "H"}
    for name, dtype in _ARRAYS.items():
        n = data.draw(st.integers(0, 7))
        setattr(msg, name, array.array(codes[dtype], _values(data, dtype, n).tobytes()))
    for name in _FLOATS:
        setattr(msg, name, data.draw(st.floats(allow_nan=True, allow_infinity=True)))
    return msg


def _assert_same(got, want):
    """Every field of ``got`` (read by the compiled pass) equals rclpy's ``want``: text, stamp, arrays' types,
    lengths and bits, floats' bits; the arrays are C-contiguous, aligned and writeable (the compiled intake's
    variant)."""
    assert (got.header.stamp.sec, got.header.stamp.nanosec) == (want.header.stamp.sec, want.header.stamp.nanosec)
    assert got.header.frame_id == want.header.frame_id and got.body_part == want.body_part
    for name, dtype in _ARRAYS.items():
        a = getattr(got, name)
        assert a.dtype == dtype and a.ndim == 1, name
        assert a.flags.c_contiguous and a.flags.aligned and a.flags.writeable, name
        assert a.tobytes() == np.frombuffer(getattr(want, name), dtype=dtype).tobytes(), name
    for name in _FLOATS:
        assert np.float64(getattr(got, name)).tobytes() == np.float64(getattr(want, name)).tobytes(), name


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_a_message_read_from_its_bytes_equals_rclpys(cdr, data):
    from rclpy.serialization import deserialize_message, serialize_message

    from tactile_descriptors_msgs.msg import SkinPartFrames

    raw = serialize_message(_message(data))
    got = cdr.read_skin_part(raw)
    assert got is not None
    _assert_same(got, deserialize_message(raw, SkinPartFrames))


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_damaged_bytes_are_refused_or_read_as_rclpy_reads_them(cdr, data):
    """Bytes cut short anywhere, or with bytes overwritten (lengths among them), never read outside the buffer:
    the pass refuses them (None) or reads what rclpy reads; where rclpy refuses, the pass does too."""
    from rclpy.serialization import deserialize_message, serialize_message

    from tactile_descriptors_msgs.msg import SkinPartFrames

    raw = bytearray(serialize_message(_message(data)))
    if data.draw(st.booleans()):
        raw = raw[:data.draw(st.integers(0, len(raw) - 1))]
    else:
        for _ in range(data.draw(st.integers(1, 4))):
            raw[data.draw(st.integers(4, len(raw) - 1))] = data.draw(st.integers(0, 255))
    raw = bytes(raw)
    got = cdr.read_skin_part(raw)
    try:
        want = deserialize_message(raw, SkinPartFrames)
    except Exception:  # noqa: BLE001 - rclpy's error type is not public
        assert got is None
        return
    if got is not None:
        _assert_same(got, want)


def test_a_message_cut_short_at_every_length_is_refused(cdr):
    from rclpy.serialization import serialize_message

    from tactile_descriptors_ros.core.robot import load_robot
    from tactile_descriptors_ros.nodes.conversions import skin_part_to_msg
    from tactile_descriptors_ros.streams.frames import SkinFrame
    from tactile_descriptors_ros.streams.skin_parts import SkinRun, pack_skin_part

    rng = np.random.default_rng(0)
    runs = [SkinRun(c.id, SkinFrame(0, rng.integers(-512, 512, (3, 10)).astype(np.int16),
                                    np.arange(10, dtype=np.int64), rng.integers(0, 4096, (3, 3)).astype(np.uint16),
                                    np.arange(3, dtype=np.int64), np.zeros(3, np.uint16)), np.zeros(3))
            for c in load_robot("nao").body_part("left_hand").cells[:3]]
    raw = serialize_message(skin_part_to_msg(pack_skin_part("left_hand", runs)))
    assert cdr.read_skin_part(raw) is not None
    # the last field (proximity_per_count) ends the payload: any shorter is a length past the end
    assert all(cdr.read_skin_part(raw[:n]) is None for n in range(len(raw)))


def test_other_encapsulations_are_left_to_rclpy(cdr):
    """Big-endian CDR (header 00 00) and XCDR2 are not read by the pass: the caller asks rclpy."""
    from rclpy.serialization import serialize_message

    from tactile_descriptors_msgs.msg import SkinPartFrames

    raw = serialize_message(SkinPartFrames())
    assert raw[:2] == b"\x00\x01" and cdr.read_skin_part(raw) is not None
    for header in (b"\x00\x00", b"\x00\x07", b"\x01\x01"):
        assert cdr.read_skin_part(header + raw[2:]) is None


def test_without_the_compiled_backend_rclpy_reads_the_bytes(cdr, monkeypatch):
    from rclpy.serialization import serialize_message

    from tactile_descriptors_msgs.msg import SkinPartFrames
    from tactile_descriptors_ros.codecs.cdr import SkinPartFramesCdr
    from tactile_descriptors_ros.nodes.conversions import skin_part_from_serialized

    msg = SkinPartFrames(body_part="chest")
    raw = serialize_message(msg)
    assert isinstance(skin_part_from_serialized(raw), SkinPartFramesCdr)
    monkeypatch.setattr(cdr, "COMPILED_CDR", False)
    assert not cdr.available() and cdr.read_skin_part(raw) is None
    back = skin_part_from_serialized(raw)
    assert isinstance(back, SkinPartFrames) and back.body_part == "chest"


def _part(data):
    """A body part's arrays (``streams.skin_parts.SkinPartFrames``) of any counts and values, and a frame id."""
    from tactile_descriptors_ros.streams.skin_parts import SkinPartFrames

    n = data.draw(st.integers(0, 5))
    a_count = np.array(data.draw(st.lists(st.integers(0, 6), min_size=n, max_size=n)), dtype=np.int64)
    f_count = np.array(data.draw(st.lists(st.integers(0, 4), min_size=n, max_size=n)), dtype=np.int64)
    n_a, n_f = int(a_count.sum()), int(f_count.sum())
    text = st.text(st.characters(blacklist_categories=("Cs",)), max_size=10)  # NUL included: rclpy cuts there
    part = SkinPartFrames(
        stamp_ns=data.draw(st.integers(0, 2**31 * 1_000_000_000 - 1)), body_part=data.draw(text),
        cell_ids=_values(data, np.uint32, n).astype(np.int64), sequence=_values(data, np.uint32, n).astype(np.int64),
        accel_count=a_count, force_count=f_count, temperature_c=_values(data, np.float64, n),
        force_tare_counts=_values(data, np.float64, 3 * n).reshape(n, 3),
        bad_frames=np.array(data.draw(st.lists(st.integers(0, 2**40), min_size=n, max_size=n)), dtype=np.int64),
        accel=_values(data, np.int16, 3 * n_a).reshape(3, n_a), accel_offset_ns=_values(data, np.int64, n_a),
        force=_values(data, np.uint16, 3 * n_f).reshape(3, n_f), force_offset_ns=_values(data, np.int64, n_f),
        proximity=_values(data, np.uint16, n_f if data.draw(st.booleans()) else 0),
        accel_mps2_per_count=data.draw(st.floats()), force_n_per_count=data.draw(st.floats()),
        proximity_per_count=data.draw(st.floats()))
    return part, data.draw(text)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_a_body_parts_bytes_written_at_once_are_the_message_rclpy_writes(cdr, data):
    """The bytes the skin driver publishes (``write_skin_part``) carry the message ``skin_part_to_msg`` builds
    of the same arrays as rclpy serialises it: rclpy reads them into the same fields (every bit; text cut at a
    NUL as rclpy cuts it), and so does the compiled reader.  They are compared through their fields: Fast CDR
    leaves padding bytes as it finds them, and its length counts the alignment of empty arrays and garbage
    after the last field (8 bytes of a message with every array empty), which is why it is never shorter."""
    from rclpy.serialization import deserialize_message, serialize_message

    from tactile_descriptors_msgs.msg import SkinPartFrames
    from tactile_descriptors_ros.nodes.conversions import skin_part_to_msg

    part, frame_id = _part(data)
    msg = skin_part_to_msg(part)
    msg.header.frame_id = frame_id
    theirs = serialize_message(msg)
    want = deserialize_message(theirs, SkinPartFrames)
    raw = cdr.write_skin_part(part, frame_id)
    assert raw is not None and len(raw) <= len(theirs)
    _assert_same(cdr.read_skin_part(serialize_message(deserialize_message(raw, SkinPartFrames))), want)
    _assert_same(cdr.read_skin_part(raw), want)


def test_a_stamp_builtin_interfaces_cannot_hold_is_refused(cdr):
    from tactile_descriptors_ros.errors import SignalError
    from tactile_descriptors_ros.streams.skin_parts import SkinPartFrames

    empty = np.zeros(0, dtype=np.int64)
    for stamp_ns in (-1, 2**31 * 1_000_000_000):
        part = SkinPartFrames(stamp_ns, "chest", empty, empty, empty, empty, np.zeros(0), np.zeros((0, 3)), empty,
                              np.zeros((3, 0), dtype=np.int16), empty, np.zeros((3, 0), dtype=np.uint16), empty)
        with pytest.raises(SignalError, match="builtin_interfaces/Time"):
            cdr.write_skin_part(part, "torso")
