"""Markers of a sample that could not be read, in decoded arrays and in messages.

An invalid sample (a parity error, an error word, a frame that never came)
is never replaced by a neighbour's value: the codecs write these markers,
the messages carry them (``BioTacFrameBatch``, ``SkinPartFrames``,
``SkinCellFrame``), and the window removes the sample and flags the body
part ``Quality.INVALID``.
"""

from __future__ import annotations

__all__ = ["INVALID_COUNT", "INVALID_ACCEL"]

#: Marker of an unreadable unsigned sample (BioTac words, skin force and proximity).
INVALID_COUNT: int = 65535
#: Marker of an unreadable signed accelerometer sample of a skin cell.
INVALID_ACCEL: int = -32768
