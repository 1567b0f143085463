"""BioTac SPI words, patterns and frames: hand-computed examples, error words, round trips."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tactile_descriptors_ros.codecs import biotac_spi as spi
from tactile_descriptors_ros.errors import (
    CodecError,
    ConfigError,
    ErrorWordError,
    FrameError,
    ParityError,
    WordFormatError,
)
from tactile_descriptors_ros.markers import INVALID_COUNT


@pytest.mark.parametrize("name,byte,channel", [
    ("PAC", 0x80, 0), ("PDC", 0x83, 1), ("TAC", 0x85, 2), ("TDC", 0x86, 3),
    ("E1", 0xA2, 17), ("E2", 0xA4, 18), ("E3", 0xA7, 19), ("E19", 0xC7, 35),
    ("E20", 0xC8, 36), ("E24", 0xD0, 40)])
def test_command_bytes_are_1SSSSSSP_with_odd_parity(name, byte, channel):
    # e.g. 0xA2 = 1 010001 0: channel 0b010001 = 17, three ones -> parity bit 0
    assert spi.command_byte(name) == byte
    assert spi.COMMAND_BYTES[name] == byte
    assert spi.channel_from_command(byte) == channel
    assert spi.channel_number(name) == channel
    assert bin(byte).count("1") % 2 == 1


def test_command_byte_checks():
    with pytest.raises(ParityError):
        spi.channel_from_command(0xA3)  # E1 with the parity bit flipped
    with pytest.raises(CodecError):
        spi.channel_from_command(0x22)  # bit 7 clear: not a sampling command
    assert spi.channel_number(0xA2) == 17  # a command byte in a pattern list
    with pytest.raises(ConfigError):
        spi.channel_number(0xA3)


@pytest.mark.parametrize("value,raw", [
    (0, b"\x01\x01"),          # 0000000|1  00000|00|1
    (4095, b"\xfe\xf8"),       # 1111111|0  11111|00|0
    (0x5A5, b"\x5b\x29"),      # 0101101|1  00101|00|1
    (1, b"\x01\x08"),          # 0000000|1  00001|00|0
    (32, b"\x02\x01"),         # 0000001|0  00000|00|1
])
def test_reply_words_hand_computed(value, raw):
    assert spi.encode_word(value) == raw
    assert spi.decode_word(raw) == value


def test_error_words_are_typed():
    for word, status in [(0xA545, spi.WordStatus.ERR_PARITY), (0xA53F, spi.WordStatus.ERR_UNKNOWN_COMMAND),
                         (0xA52D, spi.WordStatus.ERR_SAMPLING_TOO_SOON),
                         (0xA558, spi.WordStatus.ERR_UNKNOWN_CHANNEL), (0xA52E, spi.WordStatus.ERR_OTHER)]:
        raw = word.to_bytes(2, "big")
        with pytest.raises(ErrorWordError) as info:
            spi.decode_word(raw)
        assert info.value.word == word
        values, status_arr = spi.decode_words(raw)
        assert status_arr[0] == status and values[0] == INVALID_COUNT
    # 0xA5 has even parity: an undocumented 0xA5xx word is a parity error, never data
    with pytest.raises(ParityError):
        spi.decode_word(b"\xa5\x01")


def test_parity_and_padding_errors():
    with pytest.raises(ParityError):
        spi.decode_word(b"\x00\x01")  # high byte even
    with pytest.raises(ParityError):
        spi.decode_word(b"\x01\x00")  # low byte even
    with pytest.raises(WordFormatError):
        spi.decode_word(b"\x01\x07")  # parity fine (3 ones), padding bits 11
    with pytest.raises(FrameError):
        spi.decode_word(b"\x01")


def test_table_decoder_equals_bit_level_reference_on_all_words():
    raw = np.arange(65536).astype(">u2").view(np.uint8)
    v1, s1 = spi.decode_words(raw)
    v2, s2 = spi.reference_decode_words(raw)
    assert np.array_equal(v1, v2) and np.array_equal(s1, s2)
    counts = np.bincount(s1, minlength=len(spi.WordStatus))
    assert counts[spi.WordStatus.OK] == 4096  # exactly one valid word per 12-bit value
    assert counts[spi.WordStatus.PADDING] == 3 * 4096


@settings(max_examples=200, deadline=None)
@given(st.lists(st.integers(0, 4095), min_size=1, max_size=100))
def test_word_round_trip(values):
    v, s = spi.decode_words(spi.encode_words(values))
    assert v.tolist() == values and not s.any()


@settings(max_examples=300, deadline=None)
@given(st.binary(min_size=2, max_size=2))
def test_any_two_bytes_decode_or_raise_a_codec_error(raw):
    try:
        value = spi.decode_word(raw)
    except CodecError:
        assert spi.decode_words(raw)[1][0] != 0
    else:
        assert spi.encode_word(value) == raw


def test_encode_rejects_out_of_range():
    with pytest.raises(CodecError):
        spi.encode_words([4096])
    with pytest.raises(CodecError):
        spi.encode_words([-1])


# -- patterns ---------------------------------------------------------------

def test_default_pattern_and_rates():
    p = spi.FramePattern.default()
    assert p.word_count == 44 and p.pac_count == 22 and p.electrode_count == 19
    assert str(p).startswith("E1 PAC E2 PAC") and str(p).endswith("PDC PAC TAC PAC TDC PAC")
    r = p.rates(4400)
    assert r.frame_rate_hz == pytest.approx(100) and r.pac_rate_hz == pytest.approx(2200)
    assert p.command_bytes()[:4] == bytes([0xA2, 0x80, 0xA4, 0x80])
    offs = p.pac_offsets_ns(4400)
    assert offs[0] == round(1e9 / 4400)  # PAC is the second word of the frame
    assert np.allclose(np.diff(offs), 2e9 / 4400, atol=1)


def test_paper_and_sp_patterns():
    paper = spi.FramePattern.paper_50hz()
    r = paper.rates(4400)
    assert r.frame_rate_hz == pytest.approx(50) and r.pac_rate_hz == pytest.approx(2200)
    assert paper.word_count == 66 and paper.slot_count == 88 and r.words_per_s == pytest.approx(3300)
    assert np.allclose(np.diff(paper.pac_offsets_ns(4400)), 2e9 / 4400, atol=1)  # PAC stays regular
    sp = spi.FramePattern.biotac_sp()
    assert sp.electrode_count == 24 and sp.rates(4400).pac_rate_hz == pytest.approx(2200)


def test_pattern_parse_forms():
    default = spi.FramePattern.default()
    assert spi.FramePattern.parse("default") == default
    assert spi.FramePattern.parse(str(default)) == default
    assert spi.FramePattern.parse(",".join(default.names())) == default
    assert spi.FramePattern.parse(list(default.command_bytes())) == default
    assert spi.FramePattern.parse("e01 pac " + " pac ".join(f"E{i}" for i in range(2, 20)) + " pac").pac_count == 19


@pytest.mark.parametrize("spec,fragment", [
    ("", "empty"),
    ("E1 E2", "no PAC"),
    ("PAC FOO", "unknown BioTac channel"),
    ("PAC PDC PAC PDC", "appears twice"),
    ("PAC E1 PAC E2", "E1..E19"),
    ([0x81], "parity"),
    ("- -", "at least one word"),
])
def test_impossible_patterns_raise_config_error(spec, fragment):
    with pytest.raises(ConfigError) as info:
        spi.FramePattern.parse(spec)
    assert fragment in str(info.value)
    assert "frame_pattern" in str(info.value)


# -- frames -----------------------------------------------------------------

def _frame_values(pattern, seed=0):
    rng = np.random.default_rng(seed)
    pac = rng.integers(0, 4096, pattern.pac_count).tolist()
    el = rng.integers(0, 4096, pattern.electrode_count).tolist()
    vals = {"PAC": pac, "electrodes": el, "PDC": 1111, "TAC": 2222, "TDC": 3333}
    return vals, pac, el


@pytest.mark.parametrize("pattern", [spi.FramePattern.default(), spi.FramePattern.paper_50hz(),
                                     spi.FramePattern.biotac_sp()])
def test_frame_round_trip(pattern):
    vals, pac, el = _frame_values(pattern)
    raw = spi.encode_frame(pattern, vals)
    assert len(raw) == pattern.byte_count
    f = spi.BiotacFrameDecoder(pattern, sensors=(2,)).decode(2, raw, sequence=41)
    assert f.sensor == 2 and f.sequence == 41 and f.valid
    assert f.pac.tolist() == pac and f.electrodes.tolist() == el
    assert (f.pdc, f.tac, f.tdc) == (1111, 2222, 3333)


def test_default_frame_hand_computed_first_words():
    p = spi.FramePattern.default()
    vals, _, _ = _frame_values(p)
    vals["electrodes"][0] = 0
    vals["PAC"][0] = 4095
    raw = spi.encode_frame(p, vals)
    assert raw[:4] == b"\x01\x01\xfe\xf8"  # E1 = 0, then PAC = 4095


def test_bad_word_invalidates_only_its_slot():
    p = spi.FramePattern.default()
    vals, pac, el = _frame_values(p)
    raw = bytearray(spi.encode_frame(p, vals))
    raw[2 * 4: 2 * 4 + 2] = b"\xa5\x2d"   # word 4 = E3 -> "sampling too soon"
    raw[2 * 5] ^= 0x10                   # word 5 = PAC #3 -> parity
    f = spi.BiotacFrameDecoder(p).decode(0, bytes(raw))
    assert not f.electrodes_valid[2] and f.electrodes[2] == INVALID_COUNT
    assert f.electrodes_valid[[0, 1, 3]].all() and f.electrodes[3] == el[3]
    assert not f.pac_valid[2] and f.pac[2] == INVALID_COUNT
    assert f.pac[1] == pac[1] and f.pac[3] == pac[3]      # neighbours untouched, not copied
    assert f.counts.error_sampling_too_soon == 1 and f.counts.parity == 1 and f.counts.bad == 2


def test_short_reply_marks_tail_missing_without_shifting():
    p = spi.FramePattern.default()
    vals, pac, el = _frame_values(p)
    raw = spi.encode_frame(p, vals)
    f = spi.BiotacFrameDecoder(p).decode(0, raw[:41])  # 20 words and one stray byte
    assert f.counts.missing == 24
    assert f.electrodes[:10].tolist() == el[:10] and not f.electrodes_valid[10:].any()
    assert f.pac[:10].tolist() == pac[:10] and not f.pac_valid[10:].any()
    assert not (f.pdc_valid or f.tac_valid or f.tdc_valid)
    with pytest.raises(FrameError):
        spi.BiotacFrameDecoder(p).decode(0, raw + b"\x01\x01")


def test_sample_set_keeps_sensors_apart():
    p = spi.FramePattern.default()
    dec = spi.BiotacFrameDecoder(p, sensors=(0, 1, 2, 3, 4))
    replies, truth = {}, {}
    for cs in range(5):
        vals, pac, el = _frame_values(p, seed=cs)
        truth[cs] = (pac, el)
        replies[cs] = spi.encode_frame(p, vals)
    replies[1] = replies[1][:10]  # BioTac 1 answers short
    frames = dec.decode_sample_set(replies, sequence=3)
    for cs in (0, 2, 3, 4):
        assert frames[cs].pac.tolist() == truth[cs][0] and frames[cs].electrodes.tolist() == truth[cs][1]
    assert frames[1].counts.missing == 39
    assert dec.totals[1].missing == 39 and dec.totals[0].bad == 0
    with pytest.raises(CodecError):
        dec.decode(5, replies[0])


def test_decode_many_matches_decode_and_counts_sequence():
    p = spi.FramePattern.default()
    rows = [spi.encode_frame(p, _frame_values(p, s)[0]) for s in range(4)]
    dec = spi.BiotacFrameDecoder(p)
    many = dec.decode_many(0, b"".join(rows))
    assert len(many) == 4 and many.sequence.tolist() == [0, 1, 2, 3]
    one = spi.BiotacFrameDecoder(p).decode(0, rows[2], sequence=2)
    assert np.array_equal(many.frame(2).pac, one.pac) and many.frame(2).pdc == one.pdc
    assert dec.decode(0, rows[0]).sequence == 4  # continues the count
    with pytest.raises(ConfigError):
        spi.BiotacFrameDecoder(p, sensors=(0, 0))
    with pytest.raises(ConfigError):
        spi.BiotacFrameDecoder(p, sensors=(5,))


def test_property_replies():
    raw = spi.encode_property_reply("BT12-34-56.7.8-9-01-2-3456")
    assert raw.endswith(b"\x00")
    assert spi.parse_serial_number(raw) == "BT12-34-56.7.8-9-01-2-3456"
    assert spi.decode_property_reply(b"0201\xff\xff") == "0201"
    with pytest.raises(CodecError):
        spi.decode_property_reply(b"\xff")  # nothing answered
    with pytest.raises(CodecError):
        spi.parse_serial_number(b"XY123\x00")
    assert spi.property_command(spi.PROPERTY_SERIAL_NUMBER) == b"\x61\x15"


def test_responder_models_error_words():
    r = spi.BiotacSpiResponder(lambda ch: 100 + ch, electrode_count=19)
    r.transfer(bytes([spi.command_byte("PDC"), 0]))
    assert spi.decode_word(r.transfer(b"\x00\x00")) == 101
    r.transfer(bytes([0x81, 0]))  # PAC with bad parity
    assert r.transfer(b"\x00\x00") == b"\xa5\x45"
    r.transfer(bytes([spi.command_byte("E20"), 0]))  # not on a 19-electrode BioTac
    assert r.transfer(b"\x00\x00") == b"\xa5\x58"
