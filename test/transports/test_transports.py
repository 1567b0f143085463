"""Transports: registry, lifecycle, loopback, serial (loop:// and a pty), simulated, Cheetah glue."""

from __future__ import annotations

import os
import sys
import types
from array import array

import pytest

from tactile_descriptors_ros.codecs import biotac_spi as spi
from tactile_descriptors_ros.errors import ConfigError, TransportError, TransportUnavailableError
from tactile_descriptors_ros.transports import TRANSPORTS, ByteTransport, SpiSegment, create_transport, transport_class
from tactile_descriptors_ros.transports.biotac import (
    frame_segments,
    read_frame,
    read_serial_number,
    split_frame_replies,
)
from tactile_descriptors_ros.transports.simulated import SpiBus


def test_registry_names_and_errors():
    assert set(TRANSPORTS) == {"cheetah", "serial", "can", "loopback", "simulated"}
    assert issubclass(transport_class("loopback"), ByteTransport)
    with pytest.raises(ConfigError, match="unknown transport 'usb'"):
        create_transport("usb")
    with pytest.raises(ConfigError, match="unknown serial option"):
        create_transport("serial", port="loop://", speed=3)
    with pytest.raises(ConfigError, match="bad parameters"):
        create_transport("serial", prt="loop://")
    with pytest.raises(ConfigError, match="bad parameters"):
        create_transport("loopback", timeout_s="soon")


def test_loopback_lifecycle_and_timeout():
    t = create_transport("loopback")
    assert not t.is_open
    with pytest.raises(TransportError):
        t.write(b"x")
    with t:
        assert t.is_open
        assert t.write(b"hello") == 5
        assert t.read(3) == b"hel" and t.read() == b"lo"
        assert t.read(timeout_s=0.01) == b""
    assert not t.is_open
    t.close()  # idempotent


def test_serial_loop_url_and_open_failure():
    with create_transport("serial", port="loop://") as port:
        port.write(b"\x01\x02\x03")
        assert port.read(10, timeout_s=0.1) == b"\x01\x02\x03"
        assert port.read(10, timeout_s=0.01) == b""
    with pytest.raises(TransportError, match="cannot open serial port"):
        create_transport("serial", port="/dev/does-not-exist-tactile").open()


@pytest.mark.skipif(not hasattr(os, "openpty"), reason="no ptys on this system")
def test_serial_over_a_pty():
    master, slave = os.openpty()
    try:
        with create_transport("serial", port=os.ttyname(slave), baudrate=115200) as port:
            os.write(master, b"\xb1\x4e\x00")
            assert port.read(16, timeout_s=0.5) == b"\xb1\x4e\x00"
            port.write(b"ok")
            assert os.read(master, 2) == b"ok"
    finally:
        os.close(master)
        os.close(slave)


def test_can_unavailable_interface_is_reported():
    with pytest.raises((TransportUnavailableError, TransportError)):
        create_transport("can", interface="no_such_interface_xyz", channel="x").open()


class _Source:
    def __init__(self):
        self.chunks = [b"ab", b"", b"cd"]
        self.opened = self.closed = False

    def read(self, n):
        return self.chunks.pop(0) if self.chunks else b""

    def open(self):
        self.opened = True

    def close(self):
        self.closed = True


def test_simulated_byte_source_and_lifecycle():
    src = _Source()
    t = create_transport("simulated", source=src)
    with t:
        assert src.opened
        assert t.read(10) == b"ab"
        assert t.read(10, timeout_s=0.01) == b"cd"  # empty once, polled again
        t.write(b"to-device")
        assert bytes(t.written) == b"to-device"
        with pytest.raises(TransportError, match="no transfer"):
            t.transfer(0, b"\x00")
    assert src.closed
    with create_transport("simulated", source=lambda n: b"z" * n) as t2:
        assert t2.read(3) == b"zzz"


def test_simulated_spi_bus_reads_frames_and_serial_numbers():
    pattern = spi.FramePattern.default()
    devices = {cs: spi.BiotacSpiResponder(lambda ch, cs=cs: 1000 * cs + ch, serial_number=f"BT{cs:014d}")
               for cs in (0, 1, 3)}
    dec = spi.BiotacFrameDecoder(pattern, sensors=(0, 1, 3))
    with create_transport("simulated", source=SpiBus(devices)) as bus:
        frames = dec.decode_sample_set(read_frame(bus, pattern, (0, 1, 3), word_rate_hz=4400))
        assert read_serial_number(bus, 3) == "BT00000000000003"
    for cs in (0, 1, 3):
        f = frames[cs]
        assert f.valid and set(f.pac.tolist()) == {1000 * cs}
        assert f.electrodes.tolist() == [1000 * cs + 17 + e for e in range(19)]
        assert (f.pdc, f.tac, f.tdc) == (1000 * cs + 1, 1000 * cs + 2, 1000 * cs + 3)


def test_frame_segments_follow_syntouch_sequence():
    pattern = spi.FramePattern.paper_50hz()
    segs = frame_segments(pattern, (0, 2), word_rate_hz=4400)
    assert len(segs) == pattern.word_count * 3
    assert segs[0] == SpiSegment(None, bytes([0xA2, 0x00]), 50_000)      # E1 broadcast
    assert segs[1].cs == 0 and segs[2].cs == 2 and segs[1].data == b"\x00\x00"
    # the idle slot after the first PAC lengthens the pause after its last read
    assert segs[5].delay_after_ns == 10_000 + round(1e9 / 4400)
    with pytest.raises(ConfigError):
        split_frame_replies([b"\x00\x00"], pattern, (0, 2))


def test_cheetah_missing_api_is_a_clear_error():
    t = create_transport("cheetah", module="cheetah_py_not_installed_here")
    with pytest.raises(TransportUnavailableError, match="may not be redistributed"):
        t.open()


def _fake_cheetah(responders):
    """A stand-in for Total Phase's cheetah_py that runs the queued batch on BioTac models."""
    m = types.ModuleType("fake_cheetah_py")
    m.CH_PORT_NOT_FREE = 0x8000
    m.CH_SPI_BITORDER_MSB = 0
    m.CH_TARGET_POWER_ON, m.CH_TARGET_POWER_OFF = 3, 0
    state = {"queue": [], "ss": 0, "closed": False, "calls": []}
    masks = {0x01: 0, 0x02: 1, 0x04: 2, 0x05: 3, 0x06: 4}

    def rec(name, ret=0):
        def f(*a):
            state["calls"].append(name)
            return ret
        return f
    m.ch_find_devices = lambda n: (1, array("H", [7]))
    m.ch_open = lambda port: 42 if port == 7 else -1
    m.ch_status_string = lambda code: f"status {code}"
    m.ch_spi_configure = rec("configure")
    m.ch_target_power = rec("power")
    m.ch_sleep_ms = rec("sleep")
    m.ch_spi_bitrate = lambda h, khz: khz
    m.ch_spi_queue_oe = rec("oe")
    m.ch_spi_queue_clear = lambda h: state["queue"].clear()
    m.ch_spi_queue_ss = lambda h, mask: state["queue"].append(("ss", mask))
    m.ch_spi_queue_array = lambda h, data: state["queue"].append(("data", bytes(data)))
    m.ch_spi_queue_delay_ns = lambda h, ns: state["queue"].append(("delay", ns))

    def shift(h, n):
        out = bytearray()
        ss = 0
        for op, arg in state["queue"]:
            if op == "ss":
                ss = arg
            elif op == "data":
                if ss == 0x07:
                    for r in responders.values():
                        r.transfer(arg)
                    out += bytes(len(arg))
                else:
                    out += responders[masks[ss]].transfer(arg) if masks.get(ss) in responders else b"\xff" * len(arg)
        return len(out), array("B", out)
    m.ch_spi_batch_shift = shift

    def close(h):
        state["closed"] = True
    m.ch_close = close
    return m, state


def test_cheetah_glue_with_a_fake_api(monkeypatch):
    responders = {cs: spi.BiotacSpiResponder(lambda ch, cs=cs: 7 * cs + ch, serial_number=f"BT-CS{cs}")
                  for cs in (0, 3, 4)}
    fake, state = _fake_cheetah(responders)
    monkeypatch.setitem(sys.modules, "fake_cheetah_py", fake)
    pattern = spi.FramePattern.default()
    with create_transport("cheetah", module="fake_cheetah_py", bitrate_khz=4400) as ch:
        assert ch.port == 7
        replies = read_frame(ch, pattern, (0, 3, 4))
        assert read_serial_number(ch, 4) == "BT-CS4"
    assert state["closed"]
    frames = spi.BiotacFrameDecoder(pattern, sensors=(0, 3, 4)).decode_sample_set(replies)
    assert frames[4].pdc == 7 * 4 + 1 and frames[3].electrodes[0] == 21 + 17 and frames[0].valid
