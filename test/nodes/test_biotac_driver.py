"""biotac_driver: bridge framing over pyserial's loop://, SPI over a simulated bus, tare, bad words."""

from __future__ import annotations

import numpy as np
import pytest
from node_helpers import spin_until

pytestmark = pytest.mark.ros

PARAMS = {"robot": "shadow_hand", "body_parts": ["thumb", "index"], "batch_frames": 5, "tare_on_start_s": 0.0,
          "stamp_source": "device"}


def _make(ros_context, params, factory=None):
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter

    from tactile_descriptors_msgs.msg import BioTacFrameBatch
    from tactile_descriptors_ros.nodes.biotac_driver import BiotacDriver

    drv = BiotacDriver(context=ros_context, transport_factory=factory,
                       parameter_overrides=[Parameter(k, value=v) for k, v in params.items()])
    sink = rclpy.create_node("sink", context=ros_context)
    got = {"thumb": [], "index": []}
    for part in got:
        sink.create_subscription(BioTacFrameBatch, f"tactile/{part}/frames", got[part].append, 50)
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(drv)
    ex.add_node(sink)
    return drv, ex, got


def _frame_bytes(pattern, pdc, pac_base, el_base):
    from tactile_descriptors_ros.codecs.biotac_spi import encode_frame

    return encode_frame(pattern, {"PAC": [pac_base + k for k in range(pattern.pac_count)], "PDC": pdc,
                                  "TAC": 500, "TDC": 600, "electrodes": [el_base + e for e in range(19)]})


def test_bridge_over_loop_url_bad_word_stays_in_its_finger(ros_context):
    from tactile_descriptors_ros.codecs.biotac_spi import FramePattern
    from tactile_descriptors_ros.codecs.bridge_serial import BridgeEncoder, BridgeFrameType

    drv, ex, got = _make(ros_context, {**PARAMS, "transport": "serial", "serial.port": "loop://"})
    try:
        pattern = FramePattern.default()
        enc = BridgeEncoder()
        wire = enc.encode(1, b"BT0123456789ABCD", kind=BridgeFrameType.SERIAL_NUMBER)
        for k in range(10):
            for cs, base in ((0, 1000), (1, 3000)):
                payload = bytearray(_frame_bytes(pattern, 2000 + cs, base, 100 * (cs + 1)))
                if cs == 1 and k == 2:
                    payload[2 * 3 + 1] ^= 0x01  # parity error in word 3 (PAC) of index's frame 2
                wire += enc.encode(cs, bytes(payload), t_us=10_000 * k)
        drv.transport.write(wire)
        assert spin_until(ex, lambda: len(got["index"]) >= 2 and len(got["thumb"]) >= 2)
        idx = got["index"][0]
        assert idx.sensor_name == "biotac_index" and idx.chip_select == 1 and idx.frame_count == 5
        assert idx.serial_number == "BT0123456789ABCD"
        pac = np.frombuffer(idx.pac, np.uint16).reshape(5, 22)
        assert pac[2, 1] == 65535 and idx.bad_words == 1  # word 3 is the second PAC of the frame
        assert pac[2, 0] == 3000 and pac[2, 2] == 3002  # neighbours untouched, never the previous value
        thumb = np.frombuffer(got["thumb"][0].pac, np.uint16)
        assert 65535 not in thumb and got["thumb"][0].bad_words == 0  # never another finger's
        assert list(np.diff(idx.frame_offset_ns)) == [10_000_000] * 4  # from the bridge clock (t_us)
        assert list(np.frombuffer(idx.pdc, np.uint16)) == [2001] * 5
        st = {s.name.split(": ")[1]: s for s in drv.diagnostics.statuses()}
        assert st["biotac_index"].level == b"\x01"  # bad words in the last seconds
        values = {kv.key: kv.value for kv in st["biotac_index"].values}
        assert values["bad_parity"] == "1" and values["serial_number"] == "BT0123456789ABCD"
    finally:
        drv.close()


def test_tare_refused_in_contact_and_accepted_out_of_contact(ros_context):
    from std_srvs.srv import Trigger

    from tactile_descriptors_ros.codecs.biotac_spi import FramePattern
    from tactile_descriptors_ros.codecs.bridge_serial import BridgeEncoder

    drv, ex, got = _make(ros_context, {**PARAMS, "transport": "loopback", "tare_on_start_s": 0.1})
    try:
        pattern = FramePattern.default()
        enc = BridgeEncoder()

        def send(n, pdc, k0):
            drv.transport.write(b"".join(enc.encode(cs, _frame_bytes(pattern, pdc, 2000, 1000), t_us=10_000 * k)
                                         for k in range(k0, k0 + n) for cs in (0, 1)))

        send(20, 2000, 0)  # 0.2 s at rest: start tare
        assert spin_until(ex, lambda: all(s.tared for s in drv.state.values()))
        send(20, 2100, 20)  # 100 counts * 0.05 N = 5 N: in contact
        assert spin_until(ex, lambda: drv.state[1].recent_pdc and drv.state[1].recent_pdc[-1][1] == 2100)
        resp = drv._srv_tare(Trigger.Request(), Trigger.Response())
        assert not resp.success and "in contact" in resp.message
        assert spin_until(ex, lambda: any(m.pdc_tare_counts == 2000.0 for m in got["index"]))
        send(30, 2002, 40)
        # every frame read (not just the first at rest: the tare window must not straddle the contact)
        assert spin_until(ex, lambda: all(s.frames_total == 70 for s in drv.state.values()))
        resp = drv._srv_tare(Trigger.Request(), Trigger.Response())
        assert resp.success, resp.message
        assert drv.state[1].tare_pdc == pytest.approx(2002.0)
    finally:
        drv.close()


def test_spi_sampling_on_a_simulated_bus_reads_serial_numbers(ros_context):
    from tactile_descriptors_ros.codecs.biotac_spi import PAC, PDC, BiotacSpiResponder
    from tactile_descriptors_ros.transports.simulated import SimulatedTransport, SpiBus

    def device(base):
        return BiotacSpiResponder(lambda ch: base + (7 if ch == PAC else 1 if ch == PDC else 2),
                                  serial_number=f"BT{base:014d}")

    factory = lambda node: SimulatedTransport(SpiBus({0: device(1000), 1: device(2000)}))  # noqa: E731
    drv, ex, got = _make(ros_context, {**PARAMS, "transport": "simulated", "wire": "spi", "stamp_source": "clock"},
                         factory)
    try:
        # batches of 5 frames; a frame stamped before the previous one ended (the clock offset learnt a
        # smaller delay) is dropped and ends its batch early (docs/nodes.md, Time stamps)
        assert spin_until(ex, lambda: got["thumb"] and any(len(m.pac_offset_ns) == 5 * 22 for m in got["index"]))
        m = got["index"][0]
        assert m.serial_number == "BT00000000002000" and set(m.pac) == {2007} and set(m.pdc) == {2001}
        assert set(got["thumb"][0].electrodes) == {1002}
        for m in got["index"]:
            assert len(m.pac_offset_ns) in (22, 44, 66, 88, 110) and all(np.diff(m.pac_offset_ns) > 0)
    finally:
        drv.close()


def test_missing_chip_select_is_a_config_error(ros_context, tmp_path):
    import yaml
    from rclpy.parameter import Parameter

    from tactile_descriptors_ros.core.robot import robot_config_path
    from tactile_descriptors_ros.errors import ConfigError
    from tactile_descriptors_ros.nodes.biotac_driver import BiotacDriver

    data = yaml.safe_load(robot_config_path("shadow_hand").read_text())
    data["body_parts"][1]["cells"][0]["chip_select"] = 0  # index on the thumb's chip select
    path = tmp_path / "hand.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError, match="chip select 0"):
        BiotacDriver(context=ros_context, parameter_overrides=[Parameter("robot", value=str(path)),
                                                               Parameter("autostart", value=False)])
