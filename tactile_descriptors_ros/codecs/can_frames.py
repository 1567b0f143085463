"""Batches of CAN frames as one numpy record array (no python-can object per frame).

A full-body skin (NAO, 116 cells) sends about 175 000 CAN frames per second;
building or reading a :class:`can.Message` per frame costs tens of
microseconds in Python, more than the bus time of a frame.  Where frames
come in bulk (the simulator's bus, a log file, a driver draining its
receive queue) they travel as one structured array of dtype
:data:`CAN_FRAME_DTYPE`, one row per frame, and the skin decoder
(:meth:`~.skin_can.SkinCanDecoder.decode_frames`) reads it without a Python
loop over frames.

=================  =======  ===================================================
field              type     meaning
=================  =======  ===================================================
``timestamp``      float64  receive time [s] as python-can's ``Message.timestamp``
                            (0.0: unknown)
``arbitration_id`` uint32   11- or 29-bit identifier
``flags``          uint8    :data:`FLAG_EXTENDED` | :data:`FLAG_REMOTE` | :data:`FLAG_ERROR`
``dlc``            uint8    data bytes 0..8 (classic CAN)
``data``           uint8[8] data bytes; those beyond ``dlc`` are zero
=================  =======  ===================================================

:func:`frames_from_messages` and :func:`messages_from_frames` convert to and
from python-can messages losslessly for classic CAN frames (CAN FD frames,
longer than 8 bytes, are refused with :class:`~..errors.FrameError`).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np

from ..errors import FrameError

__all__ = ["CAN_FRAME_DTYPE", "FLAG_EXTENDED", "FLAG_REMOTE", "FLAG_ERROR", "empty_frames",
           "frames_from_messages", "messages_from_frames"]

#: One classic CAN frame (see the module docstring).
CAN_FRAME_DTYPE = np.dtype([("timestamp", "<f8"), ("arbitration_id", "<u4"), ("flags", "u1"), ("dlc", "u1"),
                            ("data", "u1", (8,))])
#: ``flags`` bit: 29-bit (extended) identifier.
FLAG_EXTENDED = 1
#: ``flags`` bit: remote transmission request.
FLAG_REMOTE = 2
#: ``flags`` bit: error frame.
FLAG_ERROR = 4


def empty_frames(n: int = 0) -> np.ndarray:
    """A zeroed frame array of ``n`` rows."""
    return np.zeros(int(n), dtype=CAN_FRAME_DTYPE)


def frames_from_messages(messages: Iterable[Any]) -> np.ndarray:
    """Frame array of python-can messages (in order).

    Raises
    ------
    FrameError
        A message with more than 8 data bytes (CAN FD).
    """
    msgs = list(messages)
    out = empty_frames(len(msgs))
    if not msgs:
        return out
    out["timestamp"] = [float(m.timestamp or 0.0) for m in msgs]
    out["arbitration_id"] = [int(m.arbitration_id) for m in msgs]
    out["flags"] = [(FLAG_EXTENDED if m.is_extended_id else 0) | (FLAG_REMOTE if m.is_remote_frame else 0)
                    | (FLAG_ERROR if m.is_error_frame else 0) for m in msgs]
    payload = [bytes(m.data) for m in msgs]
    lengths = np.fromiter((len(p) for p in payload), dtype=np.int64, count=len(payload))
    if lengths.size and lengths.max() > 8:
        raise FrameError(f"CAN frame of {int(lengths.max())} data bytes: only classic CAN (<= 8) is supported")
    out["dlc"] = lengths
    flat = np.frombuffer(b"".join(payload), dtype=np.uint8)
    rows = np.repeat(np.arange(len(msgs)), lengths)
    cols = np.arange(flat.size) - np.repeat(np.cumsum(lengths) - lengths, lengths)
    out["data"][rows, cols] = flat
    return out


def messages_from_frames(frames: np.ndarray) -> list[Any]:
    """python-can messages of a frame array (what a python-can bus would have delivered)."""
    import can

    out = []
    for ts, arb, flags, dlc, data in zip(frames["timestamp"].tolist(), frames["arbitration_id"].tolist(),
                                         frames["flags"].tolist(), frames["dlc"].tolist(),
                                         frames["data"].tolist()):
        out.append(can.Message(timestamp=ts, arbitration_id=arb, is_extended_id=bool(flags & FLAG_EXTENDED),
                               is_remote_frame=bool(flags & FLAG_REMOTE), is_error_frame=bool(flags & FLAG_ERROR),
                               dlc=dlc, data=bytes(data[:dlc]) if not flags & FLAG_REMOTE else None))
    return out
