"""Every conversion between ROS messages and core types, in one place.

Messages carry raw integer counts (``INVALID_COUNT`` / ``INVALID_ACCEL`` for a
sample that could not be read) and per-sample offsets from ``header.stamp``;
the core works on int64 nanosecond stamps and integer counts (exact ranks by
counting).  An invalid sample stays marked invalid all the way: it becomes
``valid = False`` in the :class:`~tactile_descriptors_ros.core.windowing.CellChunk`
and NaN force, never a neighbour's value.

Array fields are converted through ``array.array`` / ``numpy.frombuffer`` (the
generated setters accept ``array.array`` without a per-element check), so a
batch of a few thousand samples converts in microseconds.
"""

from __future__ import annotations

import array
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..codecs.cdr import read_skin_part
from ..core.aggregation import RobotDescriptor
from ..core.robot import CellType
from ..core.windowing import CellChunk, PartChunk, Window
from ..errors import ConfigError, SignalError
from ..layouts import DescriptorLayouts, layout_id
from ..markers import INVALID_ACCEL, INVALID_COUNT
from ..streams.frames import BioTacBatch, SkinFrame

__all__ = [
    "stamp_to_ns",
    "ns_to_stamp",
    "BioTacBatch",
    "biotac_batch_to_msg",
    "biotac_msg_to_batch",
    "biotac_msg_to_chunk",
    "SkinFrame",
    "skin_frame_to_msg",
    "skin_msg_to_frame",
    "skin_msg_to_chunk",
    "skin_part_to_msg",
    "skin_part_from_msg",
    "skin_part_from_serialized",
    "skin_part_msg_to_chunks",
    "skin_part_msg_to_part_chunk",
    "BIOTAC_EXTRA_CHANNELS",
    "SKIN_EXTRA_CHANNELS",
    "layout_id",
    "descriptor_to_msg",
    "descriptor_layout_to_msg",
    "DescriptorLayouts",
    "DescriptorSample",
    "descriptor_from_msg",
    "prediction_to_msg",
    "message_kind",
]



# ----------------------------------------------------------------------- time


def stamp_to_ns(stamp) -> int:
    """``builtin_interfaces/Time`` to int64 nanoseconds."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def ns_to_stamp(t_ns: int):
    """int64 nanoseconds to ``builtin_interfaces/Time``.

    Raises
    ------
    SignalError
        For negative times (a ROS time cannot be before the epoch).
    """
    from builtin_interfaces.msg import Time

    t_ns = int(t_ns)
    if t_ns < 0:
        raise SignalError(f"cannot represent a negative time ({t_ns} ns) as builtin_interfaces/Time")
    sec, nsec = divmod(t_ns, 1_000_000_000)
    return Time(sec=sec, nanosec=nsec)


def _arr(typecode: str, values: np.ndarray, dtype) -> array.array:
    out = array.array(typecode)
    out.frombytes(np.ascontiguousarray(values, dtype=dtype).tobytes())
    return out


def _np(values, dtype) -> np.ndarray:
    if isinstance(values, array.array):
        return np.frombuffer(values, dtype=dtype).copy() if len(values) else np.zeros(0, dtype)
    return np.asarray(values, dtype=dtype)


# --------------------------------------------------------------------- BioTac


def biotac_batch_to_msg(batch: BioTacBatch, *, sensor_name: str, body_part: str, chip_select: int,
                        serial_number: str = "", frame_id: str = "", pac_pa_per_count: float = 0.0,
                        pdc_pa_per_count: float = 0.0, force_n_per_count: float = 0.0,
                        pdc_tare_counts: float = 0.0, electrode_tare_counts: Sequence[float] = ()):
    """Build a ``BioTacFrameBatch`` from a decoded batch."""
    from tactile_descriptors_msgs.msg import BioTacFrameBatch

    msg = BioTacFrameBatch()
    msg.header.stamp = ns_to_stamp(batch.stamp_ns)
    msg.header.frame_id = frame_id
    msg.sensor_name = sensor_name
    msg.body_part = body_part
    msg.serial_number = serial_number
    msg.chip_select = int(chip_select)
    msg.first_frame_sequence = int(batch.first_frame_sequence) & 0xFFFFFFFF
    msg.frame_count = batch.frame_count
    msg.electrode_count = int(np.shape(batch.electrodes)[1])
    msg.pac = _arr("H", batch.pac, np.uint16)
    msg.pac_offset_ns = _arr("q", batch.pac_offset_ns, np.int64)
    msg.frame_offset_ns = _arr("q", batch.frame_offset_ns, np.int64)
    msg.pdc = _arr("H", batch.pdc, np.uint16)
    msg.tac = _arr("H", batch.tac, np.uint16)
    msg.tdc = _arr("H", batch.tdc, np.uint16)
    msg.electrodes = _arr("H", np.asarray(batch.electrodes).reshape(-1), np.uint16)
    msg.pac_pa_per_count = float(pac_pa_per_count)
    msg.pdc_pa_per_count = float(pdc_pa_per_count)
    msg.force_n_per_count = float(force_n_per_count)
    msg.pdc_tare_counts = float(pdc_tare_counts)
    msg.electrode_tare_counts = _arr("d", np.asarray(electrode_tare_counts, dtype=np.float64), np.float64)
    msg.bad_words = int(batch.bad_words)
    return msg


def biotac_msg_to_batch(msg) -> BioTacBatch:
    """Inverse of :func:`biotac_batch_to_msg` (raises SignalError for inconsistent lengths)."""
    n_f = int(msg.frame_count)
    n_e = int(msg.electrode_count)
    el = _np(msg.electrodes, np.uint16)
    if n_e == 0 or el.size != n_f * n_e:
        raise SignalError(f"{el.size} electrode samples for {n_f} frames x {n_e} electrodes")
    frame_off = _np(msg.frame_offset_ns, np.int64)
    if frame_off.size != n_f:
        raise SignalError(f"frame_count {n_f} but {frame_off.size} frame offsets")
    return BioTacBatch(
        stamp_ns=stamp_to_ns(msg.header.stamp),
        pac=_np(msg.pac, np.uint16),
        pac_offset_ns=_np(msg.pac_offset_ns, np.int64),
        frame_offset_ns=frame_off,
        pdc=_np(msg.pdc, np.uint16),
        tac=_np(msg.tac, np.uint16),
        tdc=_np(msg.tdc, np.uint16),
        electrodes=el.reshape(n_f, n_e),
        first_frame_sequence=int(msg.first_frame_sequence),
        bad_words=int(msg.bad_words),
    )


#: Extra channels (robot description ``extra_channels``) each message type carries.
BIOTAC_EXTRA_CHANNELS: tuple[str, ...] = ("pdc", "tdc", "tac")
SKIN_EXTRA_CHANNELS: tuple[str, ...] = ("proximity", "temperature")


def biotac_msg_to_chunk(msg, extra_channels: Sequence[str] = ()) -> CellChunk:
    """``BioTacFrameBatch`` -> :class:`CellChunk` (vibration PAC, deformation electrodes).

    Force (contact gate, eq. 13/16): ``(PDC - pdc_tare_counts) * force_n_per_count``
    in newtons, NaN where PDC is ``INVALID_COUNT``.  Invalid PAC or electrode
    samples are marked invalid (their values are never used).

    ``extra_channels`` (names of :data:`BIOTAC_EXTRA_CHANNELS`, in the cell
    type's order) become the chunk's extra rows, per frame: ``pdc`` tared
    (``PDC - pdc_tare_counts``), ``tdc`` and ``tac`` as counts, NaN where
    ``INVALID_COUNT``.  ``electrode_tare_counts`` (one per electrode) becomes
    the deformation tare.
    """
    b = biotac_msg_to_batch(msg)
    t0 = b.stamp_ns
    pac = b.pac.astype(np.int32)
    el = b.electrodes.astype(np.int32).T  # (n_e, frames)
    pdc = b.pdc.astype(np.float64)
    pdc_ok = b.pdc != INVALID_COUNT
    force = np.where(pdc_ok, (pdc - float(msg.pdc_tare_counts)) * float(msg.force_n_per_count), np.nan)
    extra = None
    if extra_channels:
        cols = {"pdc": np.where(pdc_ok, pdc - float(msg.pdc_tare_counts), np.nan),
                "tdc": np.where(b.tdc != INVALID_COUNT, b.tdc.astype(np.float64), np.nan),
                "tac": np.where(b.tac != INVALID_COUNT, b.tac.astype(np.float64), np.nan)}
        extra = np.stack([cols[c] for c in extra_channels])
    tare = _np(msg.electrode_tare_counts, np.float64)
    return CellChunk(
        vibration=pac[None, :],
        vibration_t_ns=t0 + b.pac_offset_ns,
        deformation=el,
        deformation_t_ns=t0 + b.frame_offset_ns,
        force_n=force,
        force_t_ns=t0 + b.frame_offset_ns,
        vibration_valid=b.pac != INVALID_COUNT,
        deformation_valid=np.all(b.electrodes != INVALID_COUNT, axis=1),
        extra=extra,
        deformation_tare=tare if tare.size == el.shape[0] else None,
    )


# ------------------------------------------------------------------ skin cell


def skin_frame_to_msg(frame: SkinFrame, *, cell_id: int, body_part: str, frame_id: str = "",
                      accel_mps2_per_count: float = 0.0, force_n_per_count: float = 0.0,
                      force_tare_counts: Sequence[float] = (0.0, 0.0, 0.0), proximity_per_count: float = 0.0):
    """Build a ``SkinCellFrame`` from decoded samples."""
    from tactile_descriptors_msgs.msg import SkinCellFrame

    msg = SkinCellFrame()
    msg.header.stamp = ns_to_stamp(frame.stamp_ns)
    msg.header.frame_id = frame_id
    msg.cell_id = int(cell_id)
    msg.body_part = body_part
    msg.sequence = int(frame.sequence) & 0xFFFFFFFF
    acc = np.asarray(frame.accel, dtype=np.int16)
    msg.accel_x = _arr("h", acc[0], np.int16)
    msg.accel_y = _arr("h", acc[1], np.int16)
    msg.accel_z = _arr("h", acc[2], np.int16)
    msg.accel_offset_ns = _arr("q", frame.accel_offset_ns, np.int64)
    msg.accel_mps2_per_count = float(accel_mps2_per_count)
    msg.force = _arr("H", np.asarray(frame.force, dtype=np.uint16).T.reshape(-1), np.uint16)
    msg.force_offset_ns = _arr("q", frame.force_offset_ns, np.int64)
    msg.force_n_per_count = float(force_n_per_count)
    msg.force_tare_counts = np.asarray(force_tare_counts, dtype=np.float64)
    msg.proximity = _arr("H", frame.proximity, np.uint16)
    msg.proximity_per_count = float(proximity_per_count)
    msg.temperature_c = float(frame.temperature_c)
    msg.bad_frames = int(frame.bad_frames)
    return msg


def skin_msg_to_frame(msg) -> SkinFrame:
    """Inverse of :func:`skin_frame_to_msg` (raises SignalError for inconsistent lengths)."""
    ax, ay, az = (_np(getattr(msg, f"accel_{a}"), np.int16) for a in "xyz")
    if not ax.size == ay.size == az.size:
        raise SignalError(f"accelerometer axes differ in length: {ax.size}, {ay.size}, {az.size}")
    force = _np(msg.force, np.uint16)
    if force.size % 3:
        raise SignalError(f"{force.size} force samples is not a multiple of 3 sensors")
    return SkinFrame(
        stamp_ns=stamp_to_ns(msg.header.stamp),
        accel=np.stack([ax, ay, az]),
        accel_offset_ns=_np(msg.accel_offset_ns, np.int64),
        force=force.reshape(-1, 3).T.copy(),
        force_offset_ns=_np(msg.force_offset_ns, np.int64),
        proximity=_np(msg.proximity, np.uint16),
        temperature_c=float(msg.temperature_c),
        sequence=int(msg.sequence),
        bad_frames=int(msg.bad_frames),
    )


def _view(values, dtype) -> np.ndarray:
    """A read-only numpy view of an rclpy array field (``array.array`` or ndarray), no copy."""
    if isinstance(values, np.ndarray):
        return values if values.dtype == dtype else values.astype(dtype)
    if isinstance(values, array.array):
        if values.itemsize != np.dtype(dtype).itemsize:
            return np.asarray(values, dtype=dtype)
        return np.frombuffer(values, dtype=dtype) if len(values) else np.zeros(0, dtype)
    return np.asarray(values, dtype=dtype)


def skin_msg_to_chunk(msg, extra_channels: Sequence[str] = ()) -> CellChunk:
    """``SkinCellFrame`` -> :class:`CellChunk` (vibration accelerometer, deformation force).

    Force (contact gate, eq. 27): the mean of the three tared force sensors
    times ``force_n_per_count``, NaN where any of them is ``INVALID_COUNT``.
    ``extra_channels`` (names of :data:`SKIN_EXTRA_CHANNELS`) become the
    chunk's extra rows, one value per force sample: ``proximity`` in counts
    (NaN where ``INVALID_COUNT`` or when the message has none), ``temperature``
    the message's ``temperature_c`` (NaN when none was read).  The force
    tare becomes the deformation tare.

    This is the window node's per-message hot path (one call per cell per
    batch: 2,320 calls/s for the NAO at 50 ms batches, 11,600 at 10 ms), so it
    reads the array fields as numpy views (``np.frombuffer`` on the
    ``array.array`` rclpy hands out) and builds only the arrays the chunk
    keeps, without the intermediate :class:`SkinFrame`; it checks the same
    lengths as :func:`skin_msg_to_frame` and raises the same errors.

    Raises
    ------
    SignalError
        For accelerometer axes of different lengths, a force array that is
        not three sensors, offsets that do not match their samples, proximity
        of the wrong length or a tare that is not three values.
    """
    ax, ay, az = _view(msg.accel_x, np.int16), _view(msg.accel_y, np.int16), _view(msg.accel_z, np.int16)
    n = ax.size
    if not n == ay.size == az.size:
        raise SignalError(f"accelerometer axes differ in length: {ax.size}, {ay.size}, {az.size}")
    off_a = _view(msg.accel_offset_ns, np.int64)
    if off_a.size != n:
        raise SignalError(f"accel must be (3, {off_a.size}), got (3, {n})")
    force = _view(msg.force, np.uint16)
    if force.size % 3:
        raise SignalError(f"{force.size} force samples is not a multiple of 3 sensors")
    m = force.size // 3
    off_f = _view(msg.force_offset_ns, np.int64)
    if off_f.size != m:
        raise SignalError(f"force must be (3, {off_f.size}), got (3, {m})")
    if len(msg.proximity) not in (0, m):
        raise SignalError(f"{len(msg.proximity)} proximity samples for {m} force samples")
    tare = _view(msg.force_tare_counts, np.float64)
    if tare.size != 3:
        raise SignalError(f"force_tare_counts must hold 3 values, got {tare.size}")
    t0 = stamp_to_ns(msg.header.stamp)
    acc = np.empty((3, n), dtype=np.int32)
    acc[0], acc[1], acc[2] = ax, ay, az
    f3 = force.reshape(m, 3).T  # (3, m) view: the message interleaves the three sensors per sample
    forces = f3.astype(np.int32)
    f_ok = (f3 != INVALID_COUNT).all(axis=0)
    mean_n = (forces - tare[:, None]).mean(axis=0) * float(msg.force_n_per_count)
    t_f = off_f + t0
    extra = None
    if extra_channels:
        prox = _view(msg.proximity, np.uint16)
        cols = {"proximity": (np.where(prox != INVALID_COUNT, prox.astype(np.float64), np.nan) if prox.size
                              else np.full(m, np.nan)),
                "temperature": np.full(m, float(msg.temperature_c))}
        extra = np.stack([cols[c] for c in extra_channels])
    return CellChunk(
        vibration=acc,
        vibration_t_ns=off_a + t0,
        deformation=forces,
        deformation_t_ns=t_f,
        force_n=np.where(f_ok, mean_n, np.nan),
        force_t_ns=t_f,
        vibration_valid=(ax != INVALID_ACCEL) & (ay != INVALID_ACCEL) & (az != INVALID_ACCEL),
        deformation_valid=f_ok,
        extra=extra,
        deformation_tare=tare,
    )


# ------------------------------------------------------- skin cells of a body part


def skin_part_to_msg(part):
    """Build a ``SkinPartFrames`` message from a :class:`~..streams.skin_parts.SkinPartFrames`."""
    from tactile_descriptors_msgs.msg import SkinPartFrames

    msg = SkinPartFrames()
    msg.header.stamp = ns_to_stamp(part.stamp_ns)
    msg.header.frame_id = part.frame_id
    msg.body_part = part.body_part
    msg.cell_ids = _arr("I", part.cell_ids, np.uint32)
    msg.sequence = _arr("I", np.asarray(part.sequence, dtype=np.int64) & 0xFFFFFFFF, np.uint32)
    msg.accel_count = _arr("I", part.accel_count, np.uint32)
    msg.force_count = _arr("I", part.force_count, np.uint32)
    msg.temperature_c = _arr("d", part.temperature_c, np.float64)
    msg.force_tare_counts = _arr("d", np.asarray(part.force_tare_counts, dtype=np.float64).reshape(-1), np.float64)
    msg.bad_frames = _arr("I", np.minimum(part.bad_frames, 0xFFFFFFFF), np.uint32)
    acc = np.asarray(part.accel, dtype=np.int16)
    msg.accel_x = _arr("h", acc[0], np.int16)
    msg.accel_y = _arr("h", acc[1], np.int16)
    msg.accel_z = _arr("h", acc[2], np.int16)
    msg.accel_offset_ns = _arr("q", part.accel_offset_ns, np.int64)
    msg.accel_mps2_per_count = float(part.accel_mps2_per_count)
    msg.force = _arr("H", np.asarray(part.force, dtype=np.uint16).T.reshape(-1), np.uint16)
    msg.force_offset_ns = _arr("q", part.force_offset_ns, np.int64)
    msg.force_n_per_count = float(part.force_n_per_count)
    msg.proximity = _arr("H", part.proximity, np.uint16)
    msg.proximity_per_count = float(part.proximity_per_count)
    return msg


def skin_part_from_msg(msg):
    """``SkinPartFrames`` (rclpy or rosbags) -> :class:`~..streams.skin_parts.SkinPartFrames`, without copies.

    The arrays are read-only numpy views of the message's fields.

    Raises
    ------
    SignalError
        For lengths that disagree with the per-run counts (accelerometer
        axes, offsets, a force array that is not three sensors, proximity,
        three tare values per run).
    """
    from ..streams.skin_parts import SkinPartFrames

    ax, ay, az = _view(msg.accel_x, np.int16), _view(msg.accel_y, np.int16), _view(msg.accel_z, np.int16)
    if not ax.size == ay.size == az.size:
        raise SignalError(f"accelerometer axes differ in length: {ax.size}, {ay.size}, {az.size}")
    force = _view(msg.force, np.uint16)
    if force.size % 3:
        raise SignalError(f"{force.size} force samples is not a multiple of 3 sensors")
    acc = np.empty((3, ax.size), dtype=np.int16)
    acc[0], acc[1], acc[2] = ax, ay, az
    return SkinPartFrames(
        stamp_ns=stamp_to_ns(msg.header.stamp),
        body_part=str(msg.body_part),
        cell_ids=_view(msg.cell_ids, np.uint32),
        sequence=_view(msg.sequence, np.uint32),
        accel_count=_view(msg.accel_count, np.uint32),
        force_count=_view(msg.force_count, np.uint32),
        temperature_c=_view(msg.temperature_c, np.float64),
        force_tare_counts=_view(msg.force_tare_counts, np.float64),
        bad_frames=_view(msg.bad_frames, np.uint32),
        accel=acc,
        accel_offset_ns=_view(msg.accel_offset_ns, np.int64),
        force=force.reshape(-1, 3).T,
        force_offset_ns=_view(msg.force_offset_ns, np.int64),
        proximity=_view(msg.proximity, np.uint16),
        accel_mps2_per_count=float(msg.accel_mps2_per_count),
        force_n_per_count=float(msg.force_n_per_count),
        proximity_per_count=float(msg.proximity_per_count),
        frame_id=str(msg.header.frame_id),
    )


def skin_part_from_serialized(raw: bytes):
    """A ``SkinPartFrames`` taken serialised, as a message: read in one compiled pass
    (:func:`~..codecs.cdr.read_skin_part`, a :class:`~..codecs.cdr.SkinPartFramesCdr`), or deserialised by
    rclpy where that pass does not serve (an rclpy message; rclpy's error for bytes it cannot read either)."""
    msg = read_skin_part(raw)
    if msg is None:
        from rclpy.serialization import deserialize_message

        from tactile_descriptors_msgs.msg import SkinPartFrames

        msg = deserialize_message(raw, SkinPartFrames)
    return msg


def skin_part_msg_to_chunks(msg, extra_channels: Sequence[str] = ()) -> list[tuple[int, CellChunk]]:
    """``SkinPartFrames`` -> ``(cell_id, CellChunk)`` per cell run (the window node's per-message path).

    :func:`skin_part_from_msg` then
    :func:`~..streams.skin_parts.skin_part_chunks`: each chunk is what
    :func:`skin_msg_to_chunk` made of the cell's ``SkinCellFrame``.

    Raises
    ------
    SignalError
        As :func:`skin_part_from_msg`.
    """
    from ..streams.skin_parts import skin_part_chunks

    return skin_part_chunks(skin_part_from_msg(msg), extra_channels)


def skin_part_msg_to_part_chunk(msg, extra_channels: Sequence[str] = ()) -> PartChunk:
    """``SkinPartFrames`` -> one :class:`PartChunk` (the window node's path: a message in one piece).

    :func:`skin_part_from_msg` then :func:`~..streams.skin_parts.skin_part_chunk`;
    ``.chunks()`` of it is :func:`skin_part_msg_to_chunks`.

    Raises
    ------
    SignalError
        As :func:`skin_part_from_msg`.
    """
    from ..streams.skin_parts import skin_part_chunk

    chunk = _part_chunk_compiled(msg, extra_channels)
    if chunk is not None:
        return chunk
    return skin_part_chunk(skin_part_from_msg(msg), extra_channels)


#: The field names and dtypes of a ``SkinPartFrames`` that :func:`.numba_kernel.skin_part_arrays` reads.
_PART_ARRAYS = (("accel_count", np.uint32), ("force_count", np.uint32), ("force_tare_counts", np.float64),
                ("accel_x", np.int16), ("accel_y", np.int16), ("accel_z", np.int16), ("accel_offset_ns", np.int64),
                ("force", np.uint16), ("force_offset_ns", np.int64))


def _part_chunk_compiled(msg, extra_channels: Sequence[str]) -> PartChunk | None:
    """:func:`skin_part_msg_to_part_chunk` by the compiled intake, equal to the bit; None where it does not serve.

    Converting a NAO body part's message took 59 us through
    :func:`skin_part_from_msg` and :func:`~..streams.skin_parts.skin_part_chunk`
    (two dozen array operations on about 140 samples); the kernel does the
    per-sample work in one pass.  It serves messages whose fields are
    writeable contiguous arrays (rclpy's ``array.array`` fields are) with
    lengths that agree with the runs' counts; any other message takes the
    numpy path, which names what is wrong with it.
    """
    from ..core import fast, windowing
    from ..streams.skin_parts import SKIN_PART_EXTRA_CHANNELS

    kernel = fast.kernel_module() if windowing.COMPILED_INTAKE else None
    if kernel is None or any(c not in SKIN_PART_EXTRA_CHANNELS for c in extra_channels):
        return None
    arrays = [_view(getattr(msg, name), dtype) for name, dtype in _PART_ARRAYS]
    proximity, temperature_c = _view(msg.proximity, np.uint16), _view(msg.temperature_c, np.float64)
    if not fast.loaded_layout(*arrays, proximity, temperature_c):
        return None  # e.g. a bag reader's read-only buffers: another compiled variant, not loaded ahead
    n = len(msg.cell_ids)
    if not (len(msg.sequence) == len(msg.bad_frames) == n):
        return None
    codes = _EXTRA_CODES.get(tuple(extra_channels))
    if codes is None:
        codes = _EXTRA_CODES[tuple(extra_channels)] = np.array(
            [SKIN_PART_EXTRA_CHANNELS.index(c) for c in extra_channels], np.int64)
    ok, a_count, f_count, acc, vib_ok, t_a, forces, f_ok, force_n, t_f, extra = kernel.skin_part_arrays(
        *arrays, stamp_to_ns(msg.header.stamp), float(msg.force_n_per_count), INVALID_ACCEL, INVALID_COUNT,
        proximity, temperature_c, codes)
    if not ok:
        return None
    return PartChunk(cell_ids=_view(msg.cell_ids, np.uint32).astype(np.int64), vibration_count=a_count,
                     deformation_count=f_count, vibration=acc, vibration_t_ns=t_a, deformation=forces,
                     deformation_t_ns=t_f, force_n=force_n, vibration_valid=vib_ok, deformation_valid=f_ok,
                     extra=extra if codes.size else None, deformation_tare=arrays[2].reshape(n, 3))


#: Extra channels asked for -> their codes in :func:`.numba_kernel.skin_part_arrays` (positions in
#: ``SKIN_PART_EXTRA_CHANNELS``: 0 proximity, 1 temperature).
_EXTRA_CODES: dict[tuple[str, ...], np.ndarray] = {}


# ----------------------------------------------------------------- descriptor


def descriptor_to_msg(desc: RobotDescriptor, window: Window, *, frame_id: str = "",
                      exploration_id: int | None = None, layout: str | None = None):
    """Build a ``Descriptor`` message for one window (stamp = window end).

    The labels are not sent: ``layout_id`` names them (``layout``, or the id of
    ``desc.labels``), and :func:`descriptor_layout_to_msg` carries them once.
    """
    from tactile_descriptors_msgs.msg import Descriptor

    msg = Descriptor()
    msg.header.stamp = ns_to_stamp(window.end_ns)
    msg.header.frame_id = frame_id
    msg.robot = desc.robot
    msg.exploration_id = int(window.exploration_id if exploration_id is None else exploration_id)
    msg.window_start = ns_to_stamp(window.start_ns)
    msg.window_end = ns_to_stamp(window.end_ns)
    msg.window_mode = window.mode
    msg.layout_mode = desc.layout
    msg.channel_mode = desc.channels
    parts = desc.body_parts
    msg.body_parts = [bp.name for bp in parts]
    msg.contact = [bool(bp.contact) for bp in parts]
    msg.cells_in_contact = _arr("H", np.array([bp.cells_in_contact for bp in parts]), np.uint16)
    msg.cells_total = _arr("H", np.array([bp.cells_total for bp in parts]), np.uint16)
    msg.mean_force_n = _arr("d", np.array([bp.mean_force_n for bp in parts], dtype=np.float64), np.float64)
    msg.quality = _arr("I", np.array([bp.quality for bp in parts]), np.uint32)
    msg.layout_id = layout if layout is not None else layout_id(desc.labels)
    msg.values = _arr("d", np.asarray(desc.values, dtype=np.float64), np.float64)
    return msg


def descriptor_layout_to_msg(desc: RobotDescriptor, *, frame_id: str = "", stamp_ns: int = 0):
    """The ``DescriptorLayout`` of a descriptor: its labels, once, under :func:`layout_id`."""
    from tactile_descriptors_msgs.msg import DescriptorLayout

    msg = DescriptorLayout()
    msg.header.stamp = ns_to_stamp(stamp_ns)
    msg.header.frame_id = frame_id
    msg.layout_id = layout_id(desc.labels)
    msg.robot = desc.robot
    msg.layout_mode = desc.layout
    msg.channel_mode = desc.channels
    msg.body_parts = [bp.name for bp in desc.body_parts]
    msg.labels = list(desc.labels)
    return msg


@dataclass
class DescriptorSample:
    """What the classifier needs from a ``Descriptor`` message."""

    exploration_id: int
    window_end_ns: int
    values: np.ndarray
    labels: tuple[str, ...]
    contact: bool
    window_mode: str
    robot: str
    body_parts: tuple[str, ...]
    frame_id: str = ""


def descriptor_from_msg(msg, labels: Sequence[str] | None = None) -> DescriptorSample:
    """``Descriptor`` -> :class:`DescriptorSample` (raises SignalError for a malformed message).

    ``labels`` are the labels of the message's layout (:class:`DescriptorLayouts`);
    a message that carries its own labels needs none.
    """
    values = _np(msg.values, np.float64)
    own = tuple(getattr(msg, "labels", ()) or ())
    labels = own if own else tuple(labels or ())
    if values.size != len(labels):
        raise SignalError(f"descriptor has {values.size} values but its layout "
                          f"{getattr(msg, 'layout_id', '') or '(none)'} {len(labels)} labels")
    n_parts = len(msg.body_parts)
    if len(msg.contact) != n_parts:
        raise SignalError(f"descriptor has {n_parts} body parts but {len(msg.contact)} contact flags")
    return DescriptorSample(
        exploration_id=int(msg.exploration_id),
        window_end_ns=stamp_to_ns(msg.window_end),
        values=values,
        labels=labels,
        contact=any(bool(c) for c in msg.contact),
        window_mode=str(msg.window_mode),
        robot=str(msg.robot),
        body_parts=tuple(msg.body_parts),
        frame_id=str(msg.header.frame_id),
    )


def prediction_to_msg(sample: DescriptorSample, *, class_name: str | None, class_names: Sequence[str],
                      scores: np.ndarray, model_version: int, updates: int, frame_id: str = ""):
    """Build a ``Prediction`` message (``has_model`` false before the first class is known).

    ``frame_id`` '' takes the descriptor's (the window node's frame: the robot's name by default).
    """
    from tactile_descriptors_msgs.msg import Prediction

    msg = Prediction()
    msg.header.stamp = ns_to_stamp(sample.window_end_ns)
    msg.header.frame_id = frame_id or sample.frame_id
    msg.exploration_id = int(sample.exploration_id)
    msg.window_end = ns_to_stamp(sample.window_end_ns)
    msg.has_model = class_name is not None
    msg.class_name = class_name or ""
    msg.class_names = list(class_names)
    msg.scores = _arr("d", np.asarray(scores, dtype=np.float64), np.float64)
    msg.model_version = int(model_version) & 0xFFFFFFFF
    msg.updates = int(updates) & 0xFFFFFFFF
    return msg


# ------------------------------------------------------------ message kinds


def message_kind(cell_type: CellType) -> str:
    """Which message carries a cell type: ``"biotac"`` or ``"skin"``.

    A cell type with one vibration channel (PAC) is a BioTac
    (``BioTacFrameBatch``); three vibration channels and three deformation
    channels are a skin cell (``SkinPartFrames``, all cells of a body part per message).

    Raises
    ------
    ConfigError
        For a cell type no message of this package carries.
    """
    n_s, n_v = len(cell_type.vibration.channels), len(cell_type.deformation.channels)
    kind = "biotac" if n_s == 1 else "skin" if n_s == 3 and n_v == 3 else None
    if kind is not None:
        carried = BIOTAC_EXTRA_CHANNELS if kind == "biotac" else SKIN_EXTRA_CHANNELS
        missing = [c for c in cell_type.extra_channels if c not in carried]
        if missing:
            raise ConfigError(f"cell type {cell_type.name!r} declares extra channel {missing[0]!r}, which "
                              f"{'BioTacFrameBatch' if kind == 'biotac' else 'SkinPartFrames'} does not carry "
                              f"(it carries {', '.join(carried)})", key=f"cell_types.{cell_type.name}.extra_channels")
        return kind
    raise ConfigError(f"no message type carries cell type {cell_type.name!r} ({n_s} vibration and {n_v} "
                      "deformation channels; BioTacFrameBatch has 1 + N, SkinPartFrames 3 + 3)",
                      key=f"cell_types.{cell_type.name}")
