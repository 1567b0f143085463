"""A body part's ``SkinPartFrames`` read from and written as its serialised (CDR) bytes in one compiled pass.

A subscription that takes its messages serialised (rclpy's ``raw=True``) is
handed the bytes rmw received; otherwise rclpy first builds a Python message
of them, an ``array.array`` per array field.  On the NAO graph's frames
(seven body parts at 100 Hz, about 4 kB a message) a bare subscriber spent
about 110 us of CPU per message it took deserialised and 45 us serialised
(``lab/docs/performance.md``, "A body part's message read and written as its
bytes").  :func:`write_skin_part` is the skin driver's side: the bytes
written from a batch's arrays in one compiled pass instead of an rclpy
message that rclpy then serialises.
:func:`read_skin_part` reads the bytes in one compiled pass
(:func:`~..core.numba_kernel.skin_part_cdr`) into a
:class:`SkinPartFramesCdr`: the message's fields under the message's names,
its arrays numpy views of one aligned copy of the bytes, so the code that
reads an rclpy message reads it unchanged.

Written by hand because no library reads CDR into numpy in one compiled call:
rosbags' deserialiser (generated Python, numpy views) cost about as much per
message as rclpy's in the same live test.  The layout is the message's
definition (``msg/msg/SkinPartFrames.msg``) in plain little-endian CDR, as
Fast DDS writes it; the tests hold every field to rclpy's own
deserialisation of the same bytes.  Bytes the pass does not read (another
encapsulation, a length past the end) give ``None``: the caller then asks
rclpy, which reads them or says why not.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core import fast
from ..errors import SignalError

__all__ = ["COMPILED_CDR", "Time", "Header", "SkinPartFramesCdr", "available", "load_compiled", "read_skin_part",
           "write_skin_part"]

#: Read serialised ``SkinPartFrames`` with the compiled pass where the compiled backend is loaded (tests switch
#: it off to compare).
COMPILED_CDR = True


@dataclass(slots=True)
class Time:
    """``builtin_interfaces/Time``."""

    sec: int
    nanosec: int


@dataclass(slots=True)
class Header:
    """``std_msgs/Header``."""

    stamp: Time
    frame_id: str


@dataclass(slots=True)
class SkinPartFramesCdr:
    """A ``SkinPartFrames`` read from its CDR bytes: the message's fields, the arrays as numpy views.

    The arrays have the message's element types (uint32, float64, int16,
    int64, uint16), are C-contiguous, aligned and writeable, and share one
    copy of the bytes.
    """

    header: Header
    body_part: str
    cell_ids: np.ndarray
    sequence: np.ndarray
    accel_count: np.ndarray
    force_count: np.ndarray
    temperature_c: np.ndarray
    force_tare_counts: np.ndarray
    bad_frames: np.ndarray
    accel_x: np.ndarray
    accel_y: np.ndarray
    accel_z: np.ndarray
    accel_offset_ns: np.ndarray
    accel_mps2_per_count: float
    force: np.ndarray
    force_offset_ns: np.ndarray
    force_n_per_count: float
    proximity: np.ndarray
    proximity_per_count: float


def available() -> bool:
    """Whether :func:`read_skin_part` reads (the compiled backend is loaded and :data:`COMPILED_CDR` is on)."""
    return COMPILED_CDR and fast.kernel_module() is not None


def load_compiled() -> bool:
    """Load the compiled passes now (from the cache ``make setup`` fills) rather than at the first message;
    whether they serve.  A node that takes or writes frames serialised calls it when it starts."""
    if not available():
        return False
    fast.warm_up_cdr(fast.kernel_module())
    return True


def _aligned(raw: bytes) -> np.ndarray:
    """A writeable copy of ``raw`` whose payload (after the 4-byte encapsulation header) starts on 8 bytes in
    memory, so every field's view is aligned for its type (CDR aligns fields from the payload's start)."""
    mem = np.empty(len(raw) // 8 + 2, dtype=np.float64).view(np.uint8)  # the allocator aligns a float64 array
    buf = mem[4:4 + len(raw)]
    buf[:] = np.frombuffer(raw, dtype=np.uint8)
    return buf


def _text(raw: bytes, start: int, count: int) -> str:
    """A CDR string's text as rclpy makes it: up to its first NUL, invalid UTF-8 replaced."""
    return raw[start:start + count].split(b"\0", 1)[0].decode("utf-8", "replace")


def read_skin_part(raw: bytes) -> SkinPartFramesCdr | None:
    """A serialised ``SkinPartFrames`` as a :class:`SkinPartFramesCdr`; None where the compiled pass does not
    serve (:func:`available`) or cannot read the bytes (another encapsulation than little-endian plain CDR, a
    length past the end).

    Reading checks the CDR framing only; whether the arrays' lengths agree
    with the runs' counts is the message's content, checked where it is used
    (as for an rclpy message).
    """
    if not available():
        return None
    (ok, sec, nanosec, starts, counts, cell_ids, sequence, accel_count, force_count, temperature_c,
     force_tare_counts, bad_frames, accel_x, accel_y, accel_z, accel_offset_ns, accel_mps2_per_count, force,
     force_offset_ns, force_n_per_count, proximity, proximity_per_count) = fast.kernel_module().skin_part_cdr(
        _aligned(raw))
    if not ok:
        return None
    return SkinPartFramesCdr(
        Header(Time(int(sec), int(nanosec)), _text(raw, int(starts[0]), int(counts[0]))),
        _text(raw, int(starts[1]), int(counts[1])), cell_ids, sequence, accel_count, force_count, temperature_c,
        force_tare_counts, bad_frames, accel_x, accel_y, accel_z, accel_offset_ns, float(accel_mps2_per_count),
        force, force_offset_ns, float(force_n_per_count), proximity, float(proximity_per_count))


def _utf8(text: str) -> np.ndarray:
    """A string field's bytes as rclpy writes them: UTF-8, up to its first NUL (rclpy copies a C string)."""
    return np.frombuffer(text.split("\0", 1)[0].encode("utf-8"), dtype=np.uint8)


def write_skin_part(part, frame_id: str) -> bytes | None:
    """The CDR bytes of the ``SkinPartFrames`` message of ``part`` (the arrays of
    :class:`~..streams.skin_parts.SkinPartFrames`) with ``header.frame_id`` = ``frame_id``, in one compiled pass
    (:func:`~..core.numba_kernel.skin_part_cdr_bytes`): the bytes rclpy serialises from the message
    ``nodes.conversions.skin_part_to_msg`` builds of it, which a publisher sends as they are.  None where the
    compiled pass does not serve (:func:`available`).

    Raises
    ------
    SignalError
        For a stamp before the epoch or past ``builtin_interfaces/Time``'s int32 seconds.
    """
    if not available():
        return None
    sec, nanosec = divmod(int(part.stamp_ns), 1_000_000_000)
    if not 0 <= sec < 2**31:
        raise SignalError(f"cannot represent {int(part.stamp_ns)} ns as builtin_interfaces/Time (int32 seconds "
                          "from the epoch)")
    i64 = np.int64
    buf = fast.kernel_module().skin_part_cdr_bytes(
        sec, nanosec, _utf8(frame_id), _utf8(part.body_part), np.ascontiguousarray(part.cell_ids, i64),
        np.ascontiguousarray(part.sequence, i64), np.ascontiguousarray(part.accel_count, i64),
        np.ascontiguousarray(part.force_count, i64), np.ascontiguousarray(part.temperature_c, np.float64),
        np.ascontiguousarray(np.reshape(part.force_tare_counts, (-1, 3)), np.float64),
        np.minimum(np.asarray(part.bad_frames, i64), 0xFFFFFFFF), np.ascontiguousarray(part.accel, np.int16),
        np.ascontiguousarray(part.accel_offset_ns, i64), float(part.accel_mps2_per_count),
        np.ascontiguousarray(part.force, np.uint16), np.ascontiguousarray(part.force_offset_ns, i64),
        float(part.force_n_per_count), np.ascontiguousarray(part.proximity, np.uint16),
        float(part.proximity_per_count))
    return buf.tobytes()
