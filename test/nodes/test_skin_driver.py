"""skin_driver over the python-can virtual bus and pyserial's loop://."""

from __future__ import annotations

import time

import can
import pytest
from node_helpers import cell_runs

from tactile_descriptors_ros.codecs.skin import Modality
from tactile_descriptors_ros.codecs.skin_can import SkinCanEncoder
from tactile_descriptors_ros.codecs.skin_serial import SkinSerialEncoder
from tactile_descriptors_ros.core.robot import load_robot

pytestmark = pytest.mark.ros


def _spin_until(executor, cond, timeout_s=10.0):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and not cond():
        executor.spin_once(timeout_sec=0.05)
    return cond()


def _make(ros_context, params, transport_factory=None):
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter

    from tactile_descriptors_msgs.msg import SkinPartFrames
    from tactile_descriptors_ros.nodes.skin_driver import SkinDriver

    drv = SkinDriver(context=ros_context, transport_factory=transport_factory,
                     parameter_overrides=[Parameter(k, value=v) for k, v in params.items()])
    sink = rclpy.create_node("sink", context=ros_context)
    got = []
    sink.create_subscription(SkinPartFrames, "tactile/left_hand/frames", got.append, 100)
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(drv)
    ex.add_node(sink)
    return drv, ex, got


def _samples(send, n_ms=400, cells=(1, 2), unknown=(999,), force=(100, 110, 120)):
    """Send n_ms of accel (1 kHz) and force (250 Hz) samples per cell, plus frames of unknown cells."""
    for k in range(n_ms):
        for c in cells + unknown:
            send(c, Modality.ACCEL, (k % 50 - 25, 3, -4))
            if k % 4 == 0:
                send(c, Modality.FORCE, force)


def test_can_virtual_bus_publishes_cells_and_reports_unknown_ids(ros_context):
    channel = f"skin_test_{time.monotonic_ns()}"
    drv, ex, got = _make(ros_context, {"robot": "nao", "transport": "can", "can.interface": "virtual",
                                       "can.channel": channel, "tare_on_start_s": 0.0, "resync_s": 0.0})
    try:
        bus = can.Bus(interface="virtual", channel=channel)
        enc = SkinCanEncoder()
        _samples(lambda c, m, v: bus.send(enc.encode(c, m, v)))
        assert _spin_until(ex, lambda: {c for m in got for c in m.cell_ids} >= {1, 2})
        assert {m.body_part for m in got} == {"left_hand"}
        # the body part's link in the TF tree (REP-120 name), as nao.yaml's geometry places it
        assert {m.header.frame_id for m in got} == {load_robot("nao").geometry.part_links["left_hand"]} == {"l_wrist"}
        # a run may hold one modality only (a read that ends between a cell's accelerometer and force frames)
        runs = lambda: [frame for _, frame, _ in cell_runs(got, 1)]  # noqa: E731
        assert _spin_until(ex, lambda: any(f.force.shape[1] for f in runs()) and any(f.accel.shape[1] for f in runs()))
        frame = next(f for f in runs() if f.accel.shape[1])
        assert frame.accel.shape[1] == len(frame.accel_offset_ns)
        assert next(f for f in runs() if f.force.shape[1]).force[:, 0].tolist() == [100, 110, 120]
        assert 999 not in {c for m in got for c in m.cell_ids}
        # both cells' batches travel together: one message per body part and batch, not one per cell
        assert any(set(m.cell_ids) == {1, 2} for m in got)
        assert len(got) < sum(len(m.cell_ids) for m in got)
        _spin_until(ex, lambda: drv.decoder.stats.unknown_cells > 0, 2.0)
        bus_status = next(s for s in drv.diagnostics.statuses() if s.name.endswith(": bus"))
        assert bus_status.level == b"\x01"
        assert "999" in bus_status.message
        bus.shutdown()
    finally:
        drv.close()


def test_serial_loop_url_and_tare(ros_context):
    drv, ex, got = _make(ros_context, {"robot": "nao", "transport": "serial", "serial.port": "loop://",
                                       "tare_on_start_s": 0.0})
    try:
        enc = SkinSerialEncoder()
        _samples(lambda c, m, v: drv.transport.write(enc.encode(c, m, v)), n_ms=300, unknown=())
        assert _spin_until(ex, lambda: any(2 in m.cell_ids for m in got))
        m = next(m for m in got if 2 in m.cell_ids)
        assert len(m.force) % 3 == 0 and len(m.force) // 3 == len(m.force_offset_ns) == sum(m.force_count)
        # tare while out of contact: ~0.24 N mean force is above the 0.2 N threshold -> refused
        from std_srvs.srv import Trigger

        resp = drv._srv_tare(Trigger.Request(), Trigger.Response())
        assert not resp.success and "contact" in resp.message
    finally:
        drv.close()


def test_unopenable_device_is_a_clear_error(ros_context):
    from rclpy.parameter import Parameter

    from tactile_descriptors_ros.errors import TransportError
    from tactile_descriptors_ros.nodes.skin_driver import SkinDriver

    with pytest.raises(TransportError, match="configure failed"):
        SkinDriver(context=ros_context, parameter_overrides=[
            Parameter("robot", value="nao"), Parameter("transport", value="serial"),
            Parameter("serial.port", value="/dev/does_not_exist_tactile")])


def test_the_compiled_decoding_and_stamping_are_loaded_before_the_bus_opens(ros_context, monkeypatch):
    """Loading them takes about 0.3 s; after the bus opened, the first read would come that much late (a
    simulated bus sheds what is more than MAX_BACKLOG_S behind, a serial port's buffer overflows).  A serial
    driver loads the stamping only."""
    from tactile_descriptors_ros.nodes import skin_driver
    from tactile_descriptors_ros.streams.link import DeviceLink

    events = []
    monkeypatch.setattr(skin_driver, "load_compiled", lambda: events.append("decoding") or True)
    monkeypatch.setattr(skin_driver, "load_stamping", lambda: events.append("stamping") or True)
    opened = DeviceLink.open
    monkeypatch.setattr(DeviceLink, "open", lambda self: (events.append("open"), opened(self))[1])
    channel = f"skin_test_{time.monotonic_ns()}"
    drv, _, _ = _make(ros_context, {"robot": "nao", "transport": "can", "can.interface": "virtual",
                                    "can.channel": channel})
    drv.close()
    assert events == ["decoding", "stamping", "open"]
    events.clear()
    drv, _, _ = _make(ros_context, {"robot": "nao", "transport": "serial", "serial.port": "loop://"})
    drv.close()
    assert events == ["stamping", "open"]
