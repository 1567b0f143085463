"""SynTouch BioTac SPI words and frames: bytes in, typed samples and counted errors out.

Wire format (SPI mode 0, MSB first; SynTouch's public
Cheetah example code):

* **Command byte** ``1SSSSSSP``: bit 7 set, a 6-bit channel number in bits
  6..1, and bit 0 chosen so the whole byte has an *odd* number of ones.
  It is followed by one don't-care byte (``0x00``).  The familiar hex values
  are complete command bytes: ``PAC 0x80`` is channel 0, ``PDC 0x83``
  channel 1, ``TAC 0x85`` channel 2, ``TDC 0x86`` channel 3 and
  ``E1..E19 0xA2..0xC7`` channels 17..35; the BioTac SP's E20..E24 are
  channels 36..40 (``0xC8 0xCB 0xCD 0xCE 0xD0``).  :func:`command_byte` and
  :func:`channel_from_command` convert both ways and check the parity.
* **Reply word** (two bytes read after the command): the high byte carries
  value bits 11..5 in bits 7..1 and odd parity in bit 0; the low byte carries
  value bits 4..0 in bits 7..3, two zero bits, and odd parity in bit 0.
  Each byte has its own odd parity.
* **Error words**: ``0xA545`` (the BioTac saw a parity error in our command),
  ``0xA53F`` (unknown command), ``0xA52D`` (sampling too soon), ``0xA558``
  (unknown channel), and four rarer documented ones counted together
  (``0xA52E 0xA55F 0xA552 0xA557``).  Their high byte ``0xA5`` has *even*
  parity, so an error word can never be mistaken for data; a ``0xA5`` high
  byte with an undocumented low byte is counted as a parity error.

A word is classified by one 65536-entry lookup table, so decoding any number
of words is one numpy gather (:func:`decode_words`).  An invalid word never
yields a number: its value is :data:`INVALID_COUNT` and its
:class:`WordStatus` says why.

A *frame* is one pass over a :class:`FramePattern` (by default 44 words,
``E1 PAC E2 PAC ... E19 PAC PDC PAC TAC PAC TDC PAC``).  Replies are decoded
by position in the pattern: a bad word invalidates exactly that sample; it is
never replaced by the previous value, and a short reply marks the missing
tail words :attr:`WordStatus.MISSING` instead of shifting later channels.

Serial numbers are read with the read command ``0x61`` followed by a property
byte (``0x15`` = serial number); the BioTac then answers one ASCII byte per
transferred byte, ending with ``0x00`` or ``0xFF`` (:func:`property_command`,
:func:`decode_property_reply`, :func:`encode_property_reply`).
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from enum import IntEnum

import numpy as np

from ..errors import CodecError, ConfigError, ErrorWordError, FrameError, ParityError, WordFormatError
from ..markers import INVALID_COUNT

__all__ = [
    "MAX_VALUE",
    "MAX_SENSORS",
    "CHANNELS",
    "PAC",
    "PDC",
    "TAC",
    "TDC",
    "IDLE",
    "electrode_channel",
    "channel_name",
    "channel_number",
    "odd_parity_bit",
    "has_odd_parity",
    "command_byte",
    "channel_from_command",
    "COMMAND_BYTES",
    "ERROR_PARITY",
    "ERROR_UNKNOWN_COMMAND",
    "ERROR_SAMPLING_TOO_SOON",
    "ERROR_UNKNOWN_CHANNEL",
    "OTHER_ERROR_WORDS",
    "ERROR_WORDS",
    "WordStatus",
    "encode_word",
    "encode_words",
    "decode_word",
    "decode_words",
    "reference_decode_words",
    "READ_COMMAND",
    "PROPERTY_FLEX_VERSION",
    "PROPERTY_FIRMWARE_VERSION",
    "PROPERTY_SERIAL_NUMBER",
    "PROPERTY_CPU_SPEED",
    "SERIAL_NUMBER_LENGTH",
    "property_command",
    "encode_property_reply",
    "decode_property_reply",
    "parse_serial_number",
    "PatternRates",
    "FramePattern",
    "WordCounts",
    "BiotacFrame",
    "BiotacFrames",
    "BiotacFrameDecoder",
    "encode_frame",
    "BiotacSpiResponder",
]

#: Largest 12-bit count.
MAX_VALUE: int = 4095
#: Most BioTacs on one SPI adapter (chip selects 0..4).
MAX_SENSORS: int = 5

PAC: int = 0
PDC: int = 1
TAC: int = 2
TDC: int = 3
#: A pattern slot that transfers no word (keeps the timing of a longer frame).
IDLE: int = -1
_E1: int = 17
_MAX_ELECTRODES: int = 24


def electrode_channel(index: int) -> int:
    """Channel number of electrode ``E<index>`` (1-based, 1..24): 17..40."""
    if not 1 <= index <= _MAX_ELECTRODES:
        raise ConfigError(f"electrode index must be 1..{_MAX_ELECTRODES}, got {index}")
    return _E1 + index - 1


#: Channel name -> 6-bit channel number.
CHANNELS: dict[str, int] = {"PAC": PAC, "PDC": PDC, "TAC": TAC, "TDC": TDC}
CHANNELS.update({f"E{i}": electrode_channel(i) for i in range(1, _MAX_ELECTRODES + 1)})
_NAMES: dict[int, str] = {v: k for k, v in CHANNELS.items()}
_NAMES[IDLE] = "-"


def channel_name(channel: int) -> str:
    """Name of a channel number (``0 -> "PAC"``, ``17 -> "E1"``, ``IDLE -> "-"``)."""
    try:
        return _NAMES[int(channel)]
    except KeyError:
        raise ConfigError(f"unknown BioTac channel number {channel}") from None


def channel_number(name: str | int) -> int:
    """Channel number of a name (``"E1"``, ``"e01"``, ``"PAC"``, ``"-"``) or a command byte.

    Integers 0..63 are channel numbers; integers 0x80..0xFF are read as full
    command bytes (parity checked) so that ``0xA2`` means E1.
    """
    if isinstance(name, (int, np.integer)):
        value = int(name)
        if value >= 0x80:
            try:
                value = channel_from_command(value)
            except CodecError as exc:
                raise ConfigError(str(exc)) from None
        if value not in _NAMES:
            raise ConfigError(f"unknown BioTac channel number {value}")
        return value
    text = str(name).strip().upper()
    if text in ("-", "IDLE"):
        return IDLE
    match = re.fullmatch(r"E0*(\d+)", text)
    if match:
        text = f"E{int(match.group(1))}"
    if text.startswith("0X"):
        return channel_number(int(text, 16))
    if text not in CHANNELS:
        raise ConfigError(
            f"unknown BioTac channel {name!r}; known: PAC, PDC, TAC, TDC, E1..E24, '-' (idle slot)"
        )
    return CHANNELS[text]


_POPCOUNT = np.array([bin(i).count("1") for i in range(256)], dtype=np.uint8)


def odd_parity_bit(bits7: int) -> int:
    """The bit that makes ``(bits7 << 1) | bit`` have an odd number of ones."""
    return 0 if _POPCOUNT[int(bits7) & 0x7F] % 2 else 1


def has_odd_parity(byte: int) -> bool:
    """True if ``byte`` has an odd number of one bits."""
    return bool(_POPCOUNT[int(byte) & 0xFF] % 2)


def command_byte(channel: int | str) -> int:
    """Sampling command byte ``1SSSSSSP`` of a channel (``"PDC"`` or 1 -> ``0x83``)."""
    ch = channel_number(channel) if isinstance(channel, str) else int(channel)
    if not 0 <= ch < 64:
        raise ConfigError(f"a BioTac channel number is 6 bits (0..63), got {ch}")
    bits7 = 0x40 | ch
    return (bits7 << 1) | odd_parity_bit(bits7)


def channel_from_command(byte: int) -> int:
    """6-bit channel number of a sampling command byte.

    Raises
    ------
    CodecError
        If bit 7 is clear (not a sampling command).
    ParityError
        If the byte does not have odd parity.
    """
    b = int(byte)
    if not 0 <= b <= 0xFF or not b & 0x80:
        raise CodecError(f"0x{b:02X} is not a BioTac sampling command (bit 7 must be set)")
    if not has_odd_parity(b):
        raise ParityError(f"command byte 0x{b:02X} fails its odd-parity check")
    return (b >> 1) & 0x3F


#: Channel name -> command byte, e.g. ``COMMAND_BYTES["E1"] == 0xA2``.
COMMAND_BYTES: dict[str, int] = {name: command_byte(ch) for name, ch in CHANNELS.items()}

ERROR_PARITY: int = 0xA545
ERROR_UNKNOWN_COMMAND: int = 0xA53F
ERROR_SAMPLING_TOO_SOON: int = 0xA52D
ERROR_UNKNOWN_CHANNEL: int = 0xA558
#: Documented but rarer error words: insufficient delay, no data to resend,
#: parameter is read-only, error writing data.
OTHER_ERROR_WORDS: tuple[int, ...] = (0xA52E, 0xA55F, 0xA552, 0xA557)


class WordStatus(IntEnum):
    """Why a reply word is (in)valid; one per word, ``OK`` only for good data."""

    OK = 0
    PARITY = 1  #: a byte failed odd parity (includes undocumented 0xA5xx words)
    PADDING = 2  #: parity fine but low-byte bits 2..1 not zero
    MISSING = 3  #: the word was not received (short reply)
    ERR_PARITY = 4  #: error word 0xA545: the BioTac saw a parity error in our command
    ERR_UNKNOWN_COMMAND = 5  #: error word 0xA53F
    ERR_SAMPLING_TOO_SOON = 6  #: error word 0xA52D
    ERR_UNKNOWN_CHANNEL = 7  #: error word 0xA558
    ERR_OTHER = 8  #: one of OTHER_ERROR_WORDS


#: Error word -> status.
ERROR_WORDS: dict[int, WordStatus] = {
    ERROR_PARITY: WordStatus.ERR_PARITY,
    ERROR_UNKNOWN_COMMAND: WordStatus.ERR_UNKNOWN_COMMAND,
    ERROR_SAMPLING_TOO_SOON: WordStatus.ERR_SAMPLING_TOO_SOON,
    ERROR_UNKNOWN_CHANNEL: WordStatus.ERR_UNKNOWN_CHANNEL,
}
ERROR_WORDS.update({w: WordStatus.ERR_OTHER for w in OTHER_ERROR_WORDS})
_N_STATUS = len(WordStatus)


def _build_tables() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    words = np.arange(65536, dtype=np.uint32)
    hi = (words >> 8).astype(np.uint8)
    lo = (words & 0xFF).astype(np.uint8)
    parity_ok = (_POPCOUNT[hi] % 2 == 1) & (_POPCOUNT[lo] % 2 == 1)
    padding_ok = (lo & 0x06) == 0
    value = (((hi.astype(np.uint16) >> 1) << 5) | (lo.astype(np.uint16) >> 3)).astype(np.uint16)
    status = np.full(65536, WordStatus.PARITY, dtype=np.uint8)
    status[parity_ok & ~padding_ok] = WordStatus.PADDING
    status[parity_ok & padding_ok] = WordStatus.OK
    for word, st in ERROR_WORDS.items():
        status[word] = st
    value_out = np.where(status == WordStatus.OK, value, INVALID_COUNT).astype(np.uint16)
    # encoder: 12-bit value -> 16-bit word
    v = np.arange(4096, dtype=np.uint16)
    hi7 = (v >> 5) & 0x7F
    lo5 = v & 0x1F
    hi_b = (hi7 << 1) | (_POPCOUNT[hi7] % 2 == 0)
    lo_b = (lo5 << 3) | (_POPCOUNT[lo5] % 2 == 0)
    enc = ((hi_b.astype(np.uint16) << 8) | lo_b.astype(np.uint16)).astype(np.uint16)
    return status, value_out, enc


_STATUS_TABLE, _VALUE_TABLE, _ENCODE_TABLE = _build_tables()
_STATUS_TABLE.setflags(write=False)
_VALUE_TABLE.setflags(write=False)
_ENCODE_TABLE.setflags(write=False)


def encode_words(values: Sequence[int] | np.ndarray) -> bytes:
    """Reply bytes (2 per value, big-endian words) for 12-bit values; for simulators.

    Raises
    ------
    CodecError
        If a value is outside 0..4095.
    """
    arr = np.asarray(values)
    if arr.size and (not np.issubdtype(arr.dtype, np.integer) or arr.min() < 0 or arr.max() > MAX_VALUE):
        raise CodecError("BioTac reply values must be integers in 0..4095")
    return _ENCODE_TABLE[arr.astype(np.intp).ravel()].astype(">u2").tobytes()


def encode_word(value: int) -> bytes:
    """The two reply bytes of one 12-bit value (``0 -> b"\\x01\\x01"``)."""
    return encode_words([int(value)])


def _as_byte_array(data: bytes | bytearray | memoryview | np.ndarray) -> np.ndarray:
    if isinstance(data, np.ndarray):
        arr = data
        if arr.dtype != np.uint8:
            raise CodecError(f"reply bytes must be uint8, got {arr.dtype}")
        return arr
    return np.frombuffer(bytes(data), dtype=np.uint8)


def decode_words(data: bytes | bytearray | memoryview | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Decode reply words, vectorised.

    Parameters
    ----------
    data : bytes or numpy.ndarray of uint8
        Reply bytes, two per word; an array may have any shape whose last
        axis has even length (``(n_frames, 2 * n_words)`` for example).

    Returns
    -------
    values : numpy.ndarray of uint16, shape (..., n_words)
        12-bit counts; :data:`INVALID_COUNT` where the word is not valid data.
    status : numpy.ndarray of uint8, shape (..., n_words)
        :class:`WordStatus` per word.

    Raises
    ------
    FrameError
        If the last axis has odd length.
    """
    arr = _as_byte_array(data)
    if arr.ndim == 0 or arr.shape[-1] % 2:
        raise FrameError(f"BioTac replies are 2 bytes per word; got {arr.shape[-1] if arr.ndim else 0} bytes")
    words = (arr[..., 0::2].astype(np.intp) << 8) | arr[..., 1::2]
    return _VALUE_TABLE[words], _STATUS_TABLE[words]


def reference_decode_words(data: bytes | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Decode words by bit arithmetic straight from the wire description (no tables).

    An independent second implementation, slower than :func:`decode_words`;
    the fuzzer and the tests compare the two.
    """
    arr = _as_byte_array(data)
    if arr.ndim == 0 or arr.shape[-1] % 2:
        raise FrameError("BioTac replies are 2 bytes per word")
    hi = arr[..., 0::2].astype(np.int64)
    lo = arr[..., 1::2].astype(np.int64)
    word = hi * 256 + lo

    def ones(x: np.ndarray) -> np.ndarray:
        return sum((x >> k) & 1 for k in range(8))

    parity_ok = (ones(hi) % 2 == 1) & (ones(lo) % 2 == 1)
    padding_ok = ((lo >> 1) & 1 == 0) & ((lo >> 2) & 1 == 0)
    status = np.where(parity_ok, np.where(padding_ok, 0, 2), 1).astype(np.uint8)
    for w, st in ERROR_WORDS.items():
        status = np.where(word == w, int(st), status).astype(np.uint8)
    value = (hi >> 1) * 32 + (lo >> 3)
    values = np.where(status == 0, value, INVALID_COUNT).astype(np.uint16)
    return values, status


def decode_word(data: bytes | Sequence[int]) -> int:
    """Decode one reply word (two bytes) to its 12-bit value.

    Raises
    ------
    ErrorWordError
        If the word is a BioTac error word (``exc.word`` holds it).
    ParityError
        If a byte fails its odd-parity check.
    WordFormatError
        If the two must-be-zero bits are set.
    FrameError
        If ``data`` is not exactly two bytes.
    """
    raw = bytes(data)
    if len(raw) != 2:
        raise FrameError(f"a BioTac reply word is 2 bytes, got {len(raw)}")
    word = (raw[0] << 8) | raw[1]
    st = WordStatus(int(_STATUS_TABLE[word]))
    if st is WordStatus.OK:
        return int(_VALUE_TABLE[word])
    if word in ERROR_WORDS:
        raise ErrorWordError(f"BioTac error word 0x{word:04X} ({st.name})", word)
    if st is WordStatus.PADDING:
        raise WordFormatError(f"reply word 0x{word:04X} has non-zero padding bits")
    raise ParityError(f"reply word 0x{word:04X} fails its odd-parity check")


# ---------------------------------------------------------------------------
# Properties (serial number)
# ---------------------------------------------------------------------------

READ_COMMAND: int = 0x61
PROPERTY_FLEX_VERSION: int = 0x10
PROPERTY_FIRMWARE_VERSION: int = 0x13
PROPERTY_SERIAL_NUMBER: int = 0x15
PROPERTY_CPU_SPEED: int = 0x61
#: Characters in a BioTac serial number (SynTouch: ``BT_SERIAL_NUMBER_READ_LENGTH``).
SERIAL_NUMBER_LENGTH: int = 16


def property_command(prop: int) -> bytes:
    """The two bytes that ask a BioTac for a property (``0x61`` then the property code)."""
    if not 0 <= int(prop) <= 0xFF:
        raise CodecError(f"property code must be one byte, got {prop}")
    return bytes([READ_COMMAND, int(prop)])


def encode_property_reply(text: str) -> bytes:
    """Bytes a BioTac sends for a text property: ASCII then a ``0x00`` terminator."""
    raw = text.encode("ascii")
    if any(b in (0x00, 0xFF) for b in raw):
        raise CodecError("a BioTac property cannot contain 0x00 or 0xFF")
    return raw + b"\x00"


def decode_property_reply(data: bytes) -> str:
    """Text of a property reply: bytes up to the first ``0x00``/``0xFF``.

    Raises
    ------
    CodecError
        If nothing came before the terminator (no BioTac answered) or a
        character is not printable ASCII.
    """
    raw = bytes(data)
    end = len(raw)
    for i, b in enumerate(raw):
        if b in (0x00, 0xFF):
            end = i
            break
    text_bytes = raw[:end]
    if not text_bytes:
        raise CodecError("empty property reply: no BioTac answered on this chip select")
    if any(b < 0x20 or b > 0x7E for b in text_bytes):
        raise CodecError(f"property reply is not printable ASCII: {text_bytes!r}")
    return text_bytes.decode("ascii")


def parse_serial_number(data: bytes) -> str:
    """Serial number from a property reply; SynTouch's own code requires the prefix ``BT``.

    Raises
    ------
    CodecError
        If the reply is empty, not ASCII, or does not start with ``BT``.
    """
    text = decode_property_reply(data)
    if not text.startswith("BT"):
        raise CodecError(f"{text!r} is not a BioTac serial number (must start with 'BT')")
    return text


# ---------------------------------------------------------------------------
# Frame pattern
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class PatternRates:
    """Sample rates that follow from a pattern and a word rate.

    Attributes
    ----------
    word_rate_hz : float
        SPI word slots per second (idle slots included).
    frame_rate_hz : float
        Frames per second; also the rate of every slow channel (PDC, TAC, TDC, electrodes).
    pac_rate_hz : float
        Mean PAC samples per second.
    words_per_s : float
        Words actually transferred per second (idle slots excluded).
    """

    word_rate_hz: float
    frame_rate_hz: float
    pac_rate_hz: float
    words_per_s: float


def _default_slots(n_electrodes: int, idle_after_pac: bool = False) -> tuple[int, ...]:
    slow = [electrode_channel(i) for i in range(1, n_electrodes + 1)] + [PDC, TAC, TDC]
    slots: list[int] = []
    for ch in slow:
        slots += [ch, PAC]
        if idle_after_pac:
            slots += [IDLE, PAC]
    return tuple(slots)


@dataclass(frozen=True)
class FramePattern:
    """The channel sequence of one frame, as data.

    Each entry is one SPI word slot: a channel number, or :data:`IDLE` for a
    slot in which no word is transferred (it only keeps time).  Rules: at
    least one PAC; every other channel at most once per frame (one sample
    per frame, like the message's ``pdc``/``tac``/``tdc``/``electrodes``);
    electrodes, if any, exactly E1..E19 (BioTac) or E1..E24 (BioTac SP).
    PDC, TAC and TDC may be left out; their samples are then never valid.

    Parameters
    ----------
    slots : tuple of int
        Channel numbers (see :data:`CHANNELS`) or ``IDLE``.
    """

    slots: tuple[int, ...]
    _cache: dict = field(default_factory=dict, init=False, repr=False, compare=False, hash=False)

    def __post_init__(self) -> None:
        slots = tuple(int(s) for s in self.slots)
        object.__setattr__(self, "slots", slots)
        if not slots or all(s == IDLE for s in slots):
            raise ConfigError("a BioTac frame pattern must contain at least one word", key="frame_pattern")
        for s in slots:
            if s not in _NAMES:
                raise ConfigError(f"unknown BioTac channel number {s} in frame pattern", key="frame_pattern")
        if PAC not in slots:
            raise ConfigError("the frame pattern has no PAC word; PAC is the vibration signal "
                              "every descriptor needs", key="frame_pattern")
        seen: set[int] = set()
        for s in slots:
            if s in (PAC, IDLE):
                continue
            if s in seen:
                raise ConfigError(f"channel {channel_name(s)} appears twice in the frame pattern; "
                                  "slow channels are sampled once per frame", key="frame_pattern")
            seen.add(s)
        electrodes = sorted(s - _E1 + 1 for s in seen if s >= _E1)
        if electrodes and electrodes != list(range(1, 20)) and electrodes != list(range(1, 25)):
            raise ConfigError(
                f"the frame pattern must sample electrodes E1..E19 (BioTac) or E1..E24 (BioTac SP) "
                f"once each; it samples {[f'E{e}' for e in electrodes]}", key="frame_pattern")
        words = [s for s in slots if s != IDLE]
        if len(words) > 256:
            raise ConfigError(f"frame pattern too long ({len(words)} words, at most 256)", key="frame_pattern")

    # -- constructors ------------------------------------------------------
    @classmethod
    def default(cls) -> FramePattern:
        """SynTouch's default 44-word frame ``E1 PAC E2 PAC ... E19 PAC PDC PAC TAC PAC TDC PAC``.

        At 4400 words/s: PAC 2.2 kHz, everything else 100 Hz.
        """
        return cls(_default_slots(19))

    @classmethod
    def paper_50hz(cls) -> FramePattern:
        """Electrodes at 50 Hz with PAC still at 2.2 kHz (the paper's rates, section III).

        88 slots: ``E1 PAC - PAC E2 PAC - PAC ... TDC PAC - PAC``; ``-`` slots
        transfer nothing.  At 4400 slots/s: frame and slow channels 50 Hz,
        PAC 2.2 kHz, 3300 words/s on the bus.  The paper does not give its
        frame; this is our construction with its rates.
        """
        return cls(_default_slots(19, idle_after_pac=True))

    @classmethod
    def biotac_sp(cls) -> FramePattern:
        """BioTac SP: 24 electrodes, ``E1 PAC ... E24 PAC PDC PAC TAC PAC TDC PAC`` (54 words).

        At 4400 words/s: PAC 2.2 kHz, frame and slow channels about 81.5 Hz.
        """
        return cls(_default_slots(24))

    @classmethod
    def parse(cls, spec: str | Sequence[str | int] | FramePattern) -> FramePattern:
        """Build a pattern from a parameter.

        Parameters
        ----------
        spec : str or sequence
            ``"default"``, ``"paper_50hz"``, ``"biotac_sp"``; or channel names
            separated by spaces/commas (``"E1 PAC E2 PAC ..."``, ``-`` for an
            idle slot); or a list of names, channel numbers or command bytes
            (``0xA2`` = E1).

        Raises
        ------
        ConfigError
            Unknown channel, empty pattern, no PAC, a slow channel twice, or an
            incomplete electrode set.
        """
        if isinstance(spec, FramePattern):
            return spec
        if isinstance(spec, str):
            key = spec.strip().lower()
            named: dict[str, Callable[[], FramePattern]] = {
                "default": cls.default, "paper_50hz": cls.paper_50hz, "biotac_sp": cls.biotac_sp}
            if key in named:
                return named[key]()
            tokens: Sequence[str | int] = [t for t in re.split(r"[\s,;]+", spec.strip()) if t]
        else:
            tokens = list(spec)
        if not tokens:
            raise ConfigError("empty BioTac frame pattern", key="frame_pattern")
        try:
            return cls(tuple(channel_number(t) for t in tokens))
        except ConfigError as exc:
            if exc.key:
                raise
            raise ConfigError(str(exc), key="frame_pattern") from None

    # -- derived -----------------------------------------------------------
    def _get(self, name: str, fn: Callable[[], object]) -> object:
        if name not in self._cache:
            self._cache[name] = fn()
        return self._cache[name]

    @property
    def words(self) -> tuple[int, ...]:
        """Channels of the transferred words (idle slots removed)."""
        return self._get("words", lambda: tuple(s for s in self.slots if s != IDLE))  # type: ignore[return-value]

    @property
    def slot_count(self) -> int:
        """Word slots per frame, idle slots included."""
        return len(self.slots)

    @property
    def word_count(self) -> int:
        """Words transferred per frame."""
        return len(self.words)

    @property
    def byte_count(self) -> int:
        """Reply bytes per frame and sensor (2 per word)."""
        return 2 * self.word_count

    @property
    def pac_count(self) -> int:
        """PAC samples per frame."""
        return self.words.count(PAC)

    @property
    def electrode_count(self) -> int:
        """Electrodes sampled (0, 19 or 24)."""
        return sum(1 for w in self.words if w >= _E1)

    def word_index(self, channel: int | str) -> int:
        """Word position of a slow channel in the frame, -1 if not sampled."""
        ch = channel_number(channel) if isinstance(channel, str) else int(channel)
        if ch == PAC:
            raise ConfigError("PAC is sampled several times per frame; use pac_word_indices")
        return self.words.index(ch) if ch in self.words else -1

    @property
    def pac_word_indices(self) -> np.ndarray:
        """Word positions of the PAC samples, in time order."""
        return self._get("pac_w", lambda: np.flatnonzero(np.asarray(self.words) == PAC))  # type: ignore[return-value]

    @property
    def electrode_word_indices(self) -> np.ndarray:
        """Word positions of E1..En (index 0 is E1)."""
        def build() -> np.ndarray:
            w = list(self.words)
            return np.array([w.index(electrode_channel(i)) for i in range(1, self.electrode_count + 1)],
                            dtype=np.intp)
        return self._get("el_w", build)  # type: ignore[return-value]

    def command_bytes(self) -> bytes:
        """The sampling command byte of each transferred word, in order."""
        return bytes(command_byte(w) for w in self.words)

    def rates(self, word_rate_hz: float = 4400.0) -> PatternRates:
        """Rates that follow from a word-slot rate (4400 slots/s by default)."""
        if not (np.isfinite(word_rate_hz) and word_rate_hz > 0):
            raise ConfigError(f"word rate must be a positive finite rate, got {word_rate_hz}", key="word_rate_hz")
        frame = word_rate_hz / self.slot_count
        return PatternRates(float(word_rate_hz), frame, frame * self.pac_count, frame * self.word_count)

    def slot_offsets_ns(self, word_rate_hz: float = 4400.0) -> np.ndarray:
        """Start time of each transferred word relative to the frame start [ns]."""
        self.rates(word_rate_hz)
        slot_idx = np.flatnonzero(np.asarray(self.slots) != IDLE)
        return np.round(slot_idx * (1e9 / word_rate_hz)).astype(np.int64)

    def pac_offsets_ns(self, word_rate_hz: float = 4400.0) -> np.ndarray:
        """Time of each PAC sample relative to the frame start [ns]."""
        return self.slot_offsets_ns(word_rate_hz)[self.pac_word_indices]

    def names(self) -> list[str]:
        """Channel names of the slots (``"-"`` for idle)."""
        return [channel_name(s) for s in self.slots]

    def __str__(self) -> str:
        return " ".join(self.names())


# ---------------------------------------------------------------------------
# Frames
# ---------------------------------------------------------------------------

_COUNT_FIELDS = ("parity", "padding", "missing", "error_parity", "error_unknown_command",
                 "error_sampling_too_soon", "error_unknown_channel", "error_other")


@dataclass(frozen=True)
class WordCounts:
    """Counts of bad words by kind (one field per non-OK :class:`WordStatus`)."""

    parity: int = 0
    padding: int = 0
    missing: int = 0
    error_parity: int = 0
    error_unknown_command: int = 0
    error_sampling_too_soon: int = 0
    error_unknown_channel: int = 0
    error_other: int = 0

    @classmethod
    def from_status(cls, status: np.ndarray) -> WordCounts:
        """Count the statuses in an array of :class:`WordStatus` codes."""
        c = np.bincount(np.asarray(status, dtype=np.intp).ravel(), minlength=_N_STATUS)
        return cls(*(int(x) for x in c[1:_N_STATUS]))

    @property
    def error_words(self) -> int:
        """Error words of any kind."""
        return (self.error_parity + self.error_unknown_command + self.error_sampling_too_soon
                + self.error_unknown_channel + self.error_other)

    @property
    def bad(self) -> int:
        """All words that did not yield a value."""
        return self.parity + self.padding + self.missing + self.error_words

    def __add__(self, other: WordCounts) -> WordCounts:
        return WordCounts(*(getattr(self, f) + getattr(other, f) for f in _COUNT_FIELDS))

    def as_dict(self) -> dict[str, int]:
        """Field name -> count."""
        return {f: getattr(self, f) for f in _COUNT_FIELDS}


@dataclass(frozen=True)
class BiotacFrame:
    """One decoded frame of one BioTac.

    Attributes
    ----------
    sensor : int
        Chip select (0..4).
    sequence : int
        Frame sequence number (from the bridge, or counted by the decoder).
    pac : numpy.ndarray of uint16, shape (pac_count,)
        PAC counts in time order; ``INVALID_COUNT`` where invalid.
    pac_valid : numpy.ndarray of bool, shape (pac_count,)
    pdc, tac, tdc : int
        Counts, ``INVALID_COUNT`` when invalid or not in the pattern.
    pdc_valid, tac_valid, tdc_valid : bool
    electrodes : numpy.ndarray of uint16, shape (electrode_count,)
        E1..En; ``INVALID_COUNT`` where invalid.
    electrodes_valid : numpy.ndarray of bool, shape (electrode_count,)
    status : numpy.ndarray of uint8, shape (word_count,)
        :class:`WordStatus` of every word in pattern order.
    counts : WordCounts
        Bad words of this frame by kind.
    """

    sensor: int
    sequence: int
    pac: np.ndarray
    pac_valid: np.ndarray
    pdc: int
    pdc_valid: bool
    tac: int
    tac_valid: bool
    tdc: int
    tdc_valid: bool
    electrodes: np.ndarray
    electrodes_valid: np.ndarray
    status: np.ndarray
    counts: WordCounts

    @property
    def valid(self) -> bool:
        """True when every word of the frame was good."""
        return self.counts.bad == 0


@dataclass(frozen=True)
class BiotacFrames:
    """Many frames of one BioTac, as arrays with a leading frame axis.

    Attributes mirror :class:`BiotacFrame`: ``pac`` (n, pac_count),
    ``pdc``/``tac``/``tdc`` (n,), ``electrodes`` (n, electrode_count), their
    ``*_valid`` masks, ``status`` (n, word_count), ``sequence`` (n,) and the
    summed ``counts``.
    """

    sensor: int
    sequence: np.ndarray
    pac: np.ndarray
    pac_valid: np.ndarray
    pdc: np.ndarray
    pdc_valid: np.ndarray
    tac: np.ndarray
    tac_valid: np.ndarray
    tdc: np.ndarray
    tdc_valid: np.ndarray
    electrodes: np.ndarray
    electrodes_valid: np.ndarray
    status: np.ndarray
    counts: WordCounts

    def __len__(self) -> int:
        return int(self.sequence.shape[0])

    def frame(self, i: int) -> BiotacFrame:
        """Frame ``i`` as a :class:`BiotacFrame`."""
        return BiotacFrame(
            sensor=self.sensor, sequence=int(self.sequence[i]),
            pac=self.pac[i], pac_valid=self.pac_valid[i],
            pdc=int(self.pdc[i]), pdc_valid=bool(self.pdc_valid[i]),
            tac=int(self.tac[i]), tac_valid=bool(self.tac_valid[i]),
            tdc=int(self.tdc[i]), tdc_valid=bool(self.tdc_valid[i]),
            electrodes=self.electrodes[i], electrodes_valid=self.electrodes_valid[i],
            status=self.status[i], counts=WordCounts.from_status(self.status[i]))


class BiotacFrameDecoder:
    """Turn the reply words of frames into :class:`BiotacFrame` objects.

    Parameters
    ----------
    pattern : FramePattern, str or sequence
        The frame pattern (anything :meth:`FramePattern.parse` accepts).
    sensors : sequence of int
        Chip selects in use, 0..4 (up to 5 BioTacs per adapter).

    Attributes
    ----------
    totals : dict[int, WordCounts]
        Bad words per sensor since construction (or :meth:`reset_counts`).
    frames_decoded : dict[int, int]
        Frames decoded per sensor.
    """

    def __init__(self, pattern: FramePattern | str | Sequence[str | int] = "default",
                 sensors: Sequence[int] = (0,)) -> None:
        self.pattern = FramePattern.parse(pattern)
        sensors = [int(s) for s in sensors]
        if not sensors:
            raise ConfigError("at least one BioTac chip select is needed", key="chip_selects")
        if len(set(sensors)) != len(sensors):
            raise ConfigError(f"chip selects repeat: {sensors}", key="chip_selects")
        bad = [s for s in sensors if not 0 <= s < MAX_SENSORS]
        if bad:
            raise ConfigError(f"chip selects must be 0..{MAX_SENSORS - 1}, got {bad}", key="chip_selects")
        self.sensors: tuple[int, ...] = tuple(sensors)
        words = self.pattern.words
        self._pac_idx = self.pattern.pac_word_indices
        self._el_idx = self.pattern.electrode_word_indices
        self._slow_idx = {ch: (words.index(ch) if ch in words else -1) for ch in (PDC, TAC, TDC)}
        self.totals: dict[int, WordCounts] = {s: WordCounts() for s in self.sensors}
        self.frames_decoded: dict[int, int] = {s: 0 for s in self.sensors}
        self._next_seq: dict[int, int] = {s: 0 for s in self.sensors}

    def reset_counts(self) -> None:
        """Zero :attr:`totals` and :attr:`frames_decoded`."""
        self.totals = {s: WordCounts() for s in self.sensors}
        self.frames_decoded = {s: 0 for s in self.sensors}

    def _check_sensor(self, sensor: int) -> int:
        s = int(sensor)
        if s not in self.totals:
            raise CodecError(f"chip select {s} is not configured (configured: {list(self.sensors)})")
        return s

    def _to_matrix(self, data: bytes | np.ndarray, n_frames: int | None) -> np.ndarray:
        """(n, byte_count) uint8 matrix, short rows padded and marked by MISSING later."""
        nbytes = self.pattern.byte_count
        arr = _as_byte_array(data)
        if arr.ndim == 1:
            if n_frames is None:
                n_frames = max(1, -(-arr.size // nbytes))
            if arr.size > n_frames * nbytes:
                raise FrameError(f"{arr.size} reply bytes is more than {n_frames} frame(s) of "
                                 f"{nbytes} bytes: the configured frame pattern does not match the device")
            return arr
        if arr.ndim != 2:
            raise FrameError(f"reply bytes must be 1-D or (n_frames, bytes), got shape {arr.shape}")
        if arr.shape[1] > nbytes:
            raise FrameError(f"frames of {arr.shape[1]} bytes are longer than the pattern's {nbytes}: "
                             "the configured frame pattern does not match the device")
        return arr

    def decode_many(self, sensor: int, data: bytes | np.ndarray, first_sequence: int | None = None,
                    lengths: np.ndarray | None = None, max_frames: int | None = None) -> BiotacFrames:
        """Decode many frames of one sensor at once.

        Parameters
        ----------
        sensor : int
            Chip select.
        data : bytes or numpy.ndarray of uint8
            Either whole frames back to back (1-D; a single reply shorter
            than one frame has its tail marked missing, as :meth:`decode`
            does) or a matrix ``(n_frames, k)`` with ``k <= byte_count``
            (columns beyond ``k`` are missing).
        first_sequence : int, optional
            Sequence number of the first frame; by default continues the
            decoder's own count for this sensor.
        lengths : numpy.ndarray of int, optional
            With a matrix: received bytes per frame (the rest of each row is
            missing), for frames truncated by different amounts.
        max_frames : int, optional
            How many frames ``data`` may hold (a bridge payload carries one).

        Raises
        ------
        FrameError
            If more bytes arrive than the pattern has words (pattern mismatch):
            1-D data longer than one frame that is not a whole number of
            frames (a BioTac SP frame read with the BioTac pattern), more
            than ``max_frames`` frames, or matrix rows longer than a frame.
        CodecError
            If the chip select is not configured.
        """
        s = self._check_sensor(sensor)
        nbytes = self.pattern.byte_count
        arr = self._to_matrix(data, None)
        if arr.ndim == 1 and arr.size > nbytes and arr.size % nbytes:
            raise FrameError(f"{arr.size} reply bytes are not a whole number of {nbytes}-byte frames: "
                             "the configured frame pattern does not match the device")
        n_in = max(1, -(-arr.size // nbytes)) if arr.ndim == 1 else arr.shape[0]
        if max_frames is not None and n_in > max_frames:
            raise FrameError(f"{arr.size if arr.ndim == 1 else arr.shape[0] * arr.shape[1]} reply bytes hold "
                             f"{n_in} frames of {nbytes} bytes where at most {max_frames} may come: the "
                             "configured frame pattern does not match the device")
        if arr.ndim == 1:
            n = max(1, -(-arr.size // nbytes))
            full = np.zeros(n * nbytes, dtype=np.uint8)
            full[: arr.size] = arr
            mat = full.reshape(n, nbytes)
            got = np.full(n, nbytes, dtype=np.intp)
            got[-1] = arr.size - (n - 1) * nbytes
        else:
            n = arr.shape[0]
            if arr.shape[1] < nbytes:
                mat = np.zeros((n, nbytes), dtype=np.uint8)
                mat[:, : arr.shape[1]] = arr
            else:
                mat = arr
            got = np.full(n, arr.shape[1], dtype=np.intp)
        if lengths is not None:
            lengths = np.asarray(lengths, dtype=np.intp)
            if lengths.shape != (n,) or np.any(lengths < 0) or np.any(lengths > got):
                raise FrameError("lengths must give 0..row-length received bytes per frame")
            got = lengths
        values, status = decode_words(mat)
        # a word is received only if both of its bytes arrived
        word_pos = np.arange(self.pattern.word_count)
        missing = (2 * word_pos[None, :] + 2) > got[:, None]
        if missing.any():
            status = status.copy()
            values = values.copy()
            status[missing] = WordStatus.MISSING
            values[missing] = INVALID_COUNT
        ok = status == WordStatus.OK
        if first_sequence is None:
            first_sequence = self._next_seq[s]
        seq = np.arange(first_sequence, first_sequence + n, dtype=np.int64)
        self._next_seq[s] = int(first_sequence + n)

        def slow(ch: int) -> tuple[np.ndarray, np.ndarray]:
            k = self._slow_idx[ch]
            if k < 0:
                return np.full(n, INVALID_COUNT, dtype=np.uint16), np.zeros(n, dtype=bool)
            return values[:, k], ok[:, k]

        pdc, pdc_ok = slow(PDC)
        tac, tac_ok = slow(TAC)
        tdc, tdc_ok = slow(TDC)
        counts = WordCounts.from_status(status)
        self.totals[s] = self.totals[s] + counts
        self.frames_decoded[s] += n
        return BiotacFrames(
            sensor=s, sequence=seq,
            pac=values[:, self._pac_idx], pac_valid=ok[:, self._pac_idx],
            pdc=pdc, pdc_valid=pdc_ok, tac=tac, tac_valid=tac_ok, tdc=tdc, tdc_valid=tdc_ok,
            electrodes=values[:, self._el_idx], electrodes_valid=ok[:, self._el_idx],
            status=status, counts=counts)

    def decode(self, sensor: int, data: bytes | np.ndarray, sequence: int | None = None) -> BiotacFrame:
        """Decode the reply bytes of one frame of one sensor.

        A reply shorter than the pattern marks its missing words
        :attr:`WordStatus.MISSING`; a longer one raises :class:`FrameError`.
        """
        s = self._check_sensor(sensor)
        arr = _as_byte_array(data)
        nbytes = self.pattern.byte_count
        if arr.ndim != 1:
            raise FrameError("decode() takes the bytes of one frame; use decode_many() for a matrix")
        if arr.size > nbytes:
            raise FrameError(f"{arr.size} reply bytes for a {nbytes}-byte frame: the "
                             "configured frame pattern does not match the device")
        n_words = arr.size // 2
        words = np.zeros(self.pattern.word_count, dtype=np.intp)
        words[:n_words] = (arr[0: 2 * n_words: 2].astype(np.intp) << 8) | arr[1: 2 * n_words: 2]
        values = _VALUE_TABLE[words]
        status = _STATUS_TABLE[words]
        if n_words < self.pattern.word_count:
            values[n_words:] = INVALID_COUNT
            status[n_words:] = WordStatus.MISSING
        ok = status == WordStatus.OK
        counts = WordCounts() if ok.all() else WordCounts.from_status(status)
        if sequence is None:
            sequence = self._next_seq[s]
        self._next_seq[s] = int(sequence) + 1
        self.totals[s] = self.totals[s] + counts
        self.frames_decoded[s] += 1

        def slow(ch: int) -> tuple[int, bool]:
            k = self._slow_idx[ch]
            if k < 0 or not ok[k]:
                return INVALID_COUNT, False
            return int(values[k]), True

        pdc, pdc_ok = slow(PDC)
        tac, tac_ok = slow(TAC)
        tdc, tdc_ok = slow(TDC)
        return BiotacFrame(
            sensor=s, sequence=int(sequence), pac=values[self._pac_idx], pac_valid=ok[self._pac_idx],
            pdc=pdc, pdc_valid=pdc_ok, tac=tac, tac_valid=tac_ok, tdc=tdc, tdc_valid=tdc_ok,
            electrodes=values[self._el_idx], electrodes_valid=ok[self._el_idx], status=status, counts=counts)

    def decode_sample_set(self, replies: Mapping[int, bytes | np.ndarray],
                          sequence: int | None = None) -> dict[int, BiotacFrame]:
        """Decode one frame from each of several sensors (chip select -> reply bytes).

        Sensors are decoded independently: a short or corrupt reply of one
        BioTac never moves values into another's frame.
        """
        return {int(cs): self.decode(cs, data, sequence) for cs, data in replies.items()}


def encode_frame(pattern: FramePattern, values: Mapping[int | str, int | Sequence[int]]) -> bytes:
    """Reply bytes of one frame from channel values; for simulators and tests.

    Parameters
    ----------
    pattern : FramePattern
    values : mapping
        Channel (name or number) -> value; PAC -> a sequence of ``pac_count``
        values in time order; electrodes ``"E1"`` ... or ``"electrodes"`` -> a
        sequence of ``electrode_count`` values.

    Raises
    ------
    CodecError
        If a channel of the pattern has no value or a value is out of range.
    """
    chan_vals: dict[int, object] = {}
    for key, val in values.items():
        if key == "electrodes":
            seq = list(val)  # type: ignore[arg-type]
            if len(seq) != pattern.electrode_count:
                raise CodecError(f"need {pattern.electrode_count} electrode values, got {len(seq)}")
            for i, v in enumerate(seq):
                chan_vals[electrode_channel(i + 1)] = v
        else:
            chan_vals[channel_number(key)] = val
    pac = chan_vals.get(PAC)
    if pac is None or len(list(pac)) != pattern.pac_count:  # type: ignore[arg-type]
        raise CodecError(f"PAC needs {pattern.pac_count} values per frame")
    pac_iter = iter(list(pac))  # type: ignore[arg-type]
    out: list[int] = []
    for w in pattern.words:
        if w == PAC:
            out.append(int(next(pac_iter)))
        else:
            if w not in chan_vals:
                raise CodecError(f"no value for channel {channel_name(w)}")
            out.append(int(chan_vals[w]))  # type: ignore[arg-type]
    return encode_words(out)


class BiotacSpiResponder:
    """Protocol model of one BioTac on the SPI bus (what it answers to what it is sent).

    For simulators and tests of SPI transports: feed it the MOSI bytes of
    each chip-select-active transfer, get the MISO bytes back.

    * a 2-byte transfer whose first byte has bit 7 set is a sampling command:
      the BioTac samples the channel (``sample(channel) -> count``); bad command
      parity queues ``0xA545``, an unknown channel ``0xA558``; MISO is zeros;
    * a 2-byte transfer of ``0x61, prop`` queues the property text
      (serial number ``0x15``, firmware ``0x13``, flex ``0x10``);
    * any other transfer is a read: it returns the queued word (or property
      bytes, then ``0x00``); with nothing queued, ``0xA55F`` (no data).

    Parameters
    ----------
    sample : callable(int) -> int
        Returns the 12-bit count of a channel number when it is sampled.
    serial_number : str
    firmware_version, flex_version : str
    electrode_count : int
        19 (BioTac) or 24 (BioTac SP): higher electrode channels are unknown.
    """

    def __init__(self, sample: Callable[[int], int], serial_number: str = "BTTEST0000000001",
                 firmware_version: str = "0201", flex_version: str = "12",
                 electrode_count: int = 19) -> None:
        self.sample = sample
        self.properties = {PROPERTY_SERIAL_NUMBER: serial_number,
                           PROPERTY_FIRMWARE_VERSION: firmware_version,
                           PROPERTY_FLEX_VERSION: flex_version}
        self.known = {PAC, PDC, TAC, TDC} | {electrode_channel(i) for i in range(1, electrode_count + 1)}
        self._pending = bytearray()

    def transfer(self, mosi: bytes) -> bytes:
        """MISO bytes for one chip-select-active transfer of ``mosi``."""
        mosi = bytes(mosi)
        if len(mosi) == 2 and mosi[0] & 0x80 and not any(mosi[1:]):
            b = mosi[0]
            if not has_odd_parity(b):
                word = ERROR_PARITY
            elif ((b >> 1) & 0x3F) not in self.known:
                word = ERROR_UNKNOWN_CHANNEL
            else:
                word = int(_ENCODE_TABLE[int(self.sample((b >> 1) & 0x3F))])
            self._pending = bytearray(word.to_bytes(2, "big"))
            return bytes(2)
        if len(mosi) == 2 and mosi[0] == READ_COMMAND:
            text = self.properties.get(mosi[1])
            if text is None:
                self._pending = bytearray(ERROR_UNKNOWN_COMMAND.to_bytes(2, "big"))
            else:
                self._pending = bytearray(encode_property_reply(text))
            return bytes(2)
        if not self._pending:
            self._pending = bytearray(0xA55F.to_bytes(2, "big"))
        out = bytearray()
        for _ in mosi:
            out.append(self._pending.pop(0) if self._pending else 0x00)
        return bytes(out)
