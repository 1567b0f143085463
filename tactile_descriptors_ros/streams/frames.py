"""Plain frame types of the stream layer: what a stream hands to a driver node.

A :class:`BioTacBatch` is one BioTac's decoded frames, a :class:`SkinFrame`
one skin cell's decoded samples; both keep raw integer counts
(:data:`~tactile_descriptors_ros.markers.INVALID_COUNT` /
:data:`~tactile_descriptors_ros.markers.INVALID_ACCEL` where a sample could
not be read) and per-sample offsets in nanoseconds from ``stamp_ns``.  The
node layer turns them into messages (``nodes/conversions.py``); nothing here
imports ROS.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import SignalError

__all__ = ["BioTacBatch", "SkinFrame"]


@dataclass
class BioTacBatch:
    """Decoded BioTac frames of one sensor, as the driver hands them to the message.

    Attributes
    ----------
    stamp_ns : int
        Time of the first PAC sample.
    pac : numpy.ndarray of uint16, shape (n_pac,)
        Counts, ``INVALID_COUNT`` where unreadable.
    pac_offset_ns : numpy.ndarray of int64, shape (n_pac,)
    frame_offset_ns : numpy.ndarray of int64, shape (n_frames,)
    pdc, tac, tdc : numpy.ndarray of uint16, shape (n_frames,)
    electrodes : numpy.ndarray of uint16, shape (n_frames, n_electrodes)
    first_frame_sequence : int
    bad_words : int
    """

    stamp_ns: int
    pac: np.ndarray
    pac_offset_ns: np.ndarray
    frame_offset_ns: np.ndarray
    pdc: np.ndarray
    tac: np.ndarray
    tdc: np.ndarray
    electrodes: np.ndarray
    first_frame_sequence: int = 0
    bad_words: int = 0

    def __post_init__(self) -> None:
        n_f = len(self.frame_offset_ns)
        if len(self.pac) != len(self.pac_offset_ns):
            raise SignalError(f"{len(self.pac)} PAC samples but {len(self.pac_offset_ns)} PAC offsets")
        for name in ("pdc", "tac", "tdc"):
            if len(getattr(self, name)) != n_f:
                raise SignalError(f"{len(getattr(self, name))} {name} samples for {n_f} frames")
        if np.ndim(self.electrodes) != 2 or np.shape(self.electrodes)[0] != n_f:
            raise SignalError(f"electrodes must be (frames={n_f}, n_electrodes), got {np.shape(self.electrodes)}")

    @property
    def frame_count(self) -> int:
        return len(self.frame_offset_ns)


@dataclass
class SkinFrame:
    """Decoded samples of one skin cell, as the driver hands them to the message.

    Attributes
    ----------
    stamp_ns : int
        Time of the first accelerometer sample.
    accel : numpy.ndarray of int16, shape (3, n_accel)
        x, y, z counts; ``INVALID_ACCEL`` where unreadable.
    accel_offset_ns : numpy.ndarray of int64, shape (n_accel,)
    force : numpy.ndarray of uint16, shape (3, n_force)
        Three force sensors; ``INVALID_COUNT`` where unreadable.
    force_offset_ns : numpy.ndarray of int64, shape (n_force,)
    proximity : numpy.ndarray of uint16, shape (n_force,) or (0,)
    temperature_c : float
        NaN when none was read.
    """

    stamp_ns: int
    accel: np.ndarray
    accel_offset_ns: np.ndarray
    force: np.ndarray
    force_offset_ns: np.ndarray
    proximity: np.ndarray
    temperature_c: float = float("nan")
    sequence: int = 0
    bad_frames: int = 0

    def __post_init__(self) -> None:
        if np.ndim(self.accel) != 2 or np.shape(self.accel)[0] != 3 or \
                np.shape(self.accel)[1] != len(self.accel_offset_ns):
            raise SignalError(f"accel must be (3, {len(self.accel_offset_ns)}), got {np.shape(self.accel)}")
        if np.ndim(self.force) != 2 or np.shape(self.force)[0] != 3 or \
                np.shape(self.force)[1] != len(self.force_offset_ns):
            raise SignalError(f"force must be (3, {len(self.force_offset_ns)}), got {np.shape(self.force)}")
        if len(self.proximity) not in (0, len(self.force_offset_ns)):
            raise SignalError(f"{len(self.proximity)} proximity samples for {len(self.force_offset_ns)} force samples")
