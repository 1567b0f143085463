"""BioTac over an SPI transport: the transfers of one frame, and property reads.

The sampling sequence is SynTouch's: for each word of the frame pattern the
command byte and a don't-care byte go to *all* BioTacs at once (chip select
broadcast), then after a pause each BioTac is selected in turn and two zero
bytes clock its reply out.  One frame for ``n`` BioTacs is thus
``word_count * (1 + n)`` transfers, queued as one batch.  Idle slots of a
pattern become a pause of one word time.
"""

from __future__ import annotations

from collections.abc import Sequence

from ..codecs.biotac_spi import (
    IDLE,
    PROPERTY_SERIAL_NUMBER,
    SERIAL_NUMBER_LENGTH,
    FramePattern,
    command_byte,
    decode_property_reply,
    parse_serial_number,
    property_command,
)
from ..errors import ConfigError
from .base import SpiSegment, SpiTransport

__all__ = ["AFTER_SAMPLE_DELAY_NS", "INTERWORD_DELAY_NS", "frame_segments", "split_frame_replies",
           "read_frame", "read_property", "read_serial_number"]

#: Pause after a sampling command before the replies are read (SynTouch default) [ns].
AFTER_SAMPLE_DELAY_NS = 50_000
#: Pause between words (SynTouch default) [ns].
INTERWORD_DELAY_NS = 10_000


def frame_segments(pattern: FramePattern, sensors: Sequence[int], word_rate_hz: float | None = None,
                   after_sample_delay_ns: int = AFTER_SAMPLE_DELAY_NS,
                   interword_delay_ns: int = INTERWORD_DELAY_NS) -> list[SpiSegment]:
    """The SPI transfers of one frame for the given chip selects.

    With ``word_rate_hz`` idle slots become pauses of one word time
    (``1e9 / word_rate_hz`` ns); without it they are skipped.
    """
    if not sensors:
        raise ConfigError("at least one chip select is needed", key="chip_selects")
    segs: list[SpiSegment] = []
    idle_ns = int(round(1e9 / word_rate_hz)) if word_rate_hz else 0
    for slot in pattern.slots:
        if slot == IDLE:
            if idle_ns and segs:
                last = segs[-1]
                segs[-1] = SpiSegment(last.cs, last.data, last.delay_after_ns + idle_ns)
            continue
        segs.append(SpiSegment(None, bytes([command_byte(slot), 0x00]), after_sample_delay_ns))
        for i, cs in enumerate(sensors):
            delay = interword_delay_ns if i == len(sensors) - 1 else 0
            segs.append(SpiSegment(int(cs), b"\x00\x00", delay))
    return segs


def split_frame_replies(replies: Sequence[bytes], pattern: FramePattern,
                        sensors: Sequence[int]) -> dict[int, bytes]:
    """Per chip select, the reply bytes of one frame from the MISO of :func:`frame_segments`."""
    n = len(sensors)
    expected = pattern.word_count * (1 + n)
    if len(replies) != expected:
        raise ConfigError(f"{len(replies)} transfers for a frame of {expected}: segments and pattern differ")
    out = {int(cs): bytearray() for cs in sensors}
    for w in range(pattern.word_count):
        base = w * (1 + n) + 1
        for i, cs in enumerate(sensors):
            out[int(cs)] += replies[base + i]
    return {cs: bytes(b) for cs, b in out.items()}


def read_frame(spi: SpiTransport, pattern: FramePattern, sensors: Sequence[int],
               word_rate_hz: float | None = None) -> dict[int, bytes]:
    """Sample one frame from every BioTac; chip select -> reply bytes for
    :meth:`~..codecs.biotac_spi.BiotacFrameDecoder.decode_sample_set`."""
    segs = frame_segments(pattern, sensors, word_rate_hz)
    return split_frame_replies(spi.transfer_batch(segs), pattern, sensors)


def read_property(spi: SpiTransport, cs: int, prop: int, max_length: int = 100) -> str:
    """Read a text property (``0x61`` + property code, then one byte per transfer).

    Raises
    ------
    CodecError
        If nothing answered or the reply is not text.
    """
    spi.transfer_batch([SpiSegment(int(cs), property_command(prop), AFTER_SAMPLE_DELAY_NS)])
    raw = bytearray()
    for _ in range(max_length):
        b = spi.transfer(int(cs), b"\x00")
        raw += b
        if b[0] in (0x00, 0xFF):
            break
    return decode_property_reply(bytes(raw))


def read_serial_number(spi: SpiTransport, cs: int) -> str:
    """Serial number of the BioTac on ``cs`` (``"BT..."``)."""
    text = read_property(spi, cs, PROPERTY_SERIAL_NUMBER, max_length=SERIAL_NUMBER_LENGTH + 4)
    return parse_serial_number(text.encode("ascii"))
