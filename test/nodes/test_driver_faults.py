"""Drivers under attack: an unplugged and replugged serial BioTac and CAN adapter, payloads of another
pattern, a failure while handling a read, a skin cell that goes quiet for longer than its sequence wraps."""

from __future__ import annotations

import os
import threading
import time
import tty

import numpy as np
import pytest
from node_helpers import cell_runs, spin_until

pytestmark = pytest.mark.ros

PARAMS = {"robot": "shadow_hand", "body_parts": ["thumb", "index"], "batch_frames": 5, "tare_on_start_s": 0.0}


def _make_biotac(ros_context, params, factory=None):
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
        sink.create_subscription(BioTacFrameBatch, f"tactile/{part}/frames", got[part].append, 500)
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(drv)
    ex.add_node(sink)
    # the sink must be matched before data flows (a message published before is not delivered)
    assert spin_until(ex, lambda: all(p.get_subscription_count() > 0 for p in drv.publishers_by_cs.values()))
    return drv, ex, got


def _payload(pattern, pdc=2000):
    from tactile_descriptors_ros.codecs.biotac_spi import encode_frame

    return encode_frame(pattern, {"PAC": [2000 + k for k in range(pattern.pac_count)], "PDC": pdc, "TAC": 500,
                                  "TDC": 600, "electrodes": [1000 + e for e in range(pattern.electrode_count)]})


def _statuses(drv):
    return {s.name.split(": ")[1]: s for s in drv.diagnostics.statuses()}


def _values(status):
    return {kv.key: kv.value for kv in status.values}


class _Bridge:
    """A BioTac bridge on a pty behind a stable name (as udev's /dev/serial/by-id links): frames of chip
    selects 0 and 1 at 100 Hz from a thread; ``unplug`` closes the pty and removes the name, as udev
    does, ``replug`` makes a new pty and names it again.

    The name must go with the pty: the kernel gives a freed pty number to the next pty opened on the
    machine (another test's, a terminal's), and a name left pointing at it would hand the driver a
    stranger's device that never sends a frame.
    """

    def __init__(self, link_path) -> None:
        from tactile_descriptors_ros.codecs.biotac_spi import FramePattern
        from tactile_descriptors_ros.codecs.bridge_serial import BridgeEncoder

        self.link_path = link_path
        self.payload = _payload(FramePattern.default())
        self.enc = BridgeEncoder()
        self.k = 0
        self.lock = threading.Lock()
        self.master = None
        self.slave = None
        self.stop = threading.Event()
        self.replug()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def replug(self) -> None:
        master, slave = os.openpty()
        tty.setraw(slave)
        os.set_blocking(master, False)  # a full pty (nobody reading) drops frames, never blocks the writer
        tmp = f"{self.link_path}.new"
        os.symlink(os.ttyname(slave), tmp)
        with self.lock:
            self.enc = type(self.enc)()  # the bridge restarted: numbers and clock start again
            self.k = 0
            self.master, self.slave = master, slave
        os.replace(tmp, self.link_path)

    def unplug(self) -> None:
        with self.lock:
            master, slave, self.master, self.slave = self.master, self.slave, None, None
        os.unlink(self.link_path)
        os.close(master)
        os.close(slave)

    def _run(self) -> None:
        while not self.stop.wait(0.01):
            with self.lock:
                if self.master is None:
                    continue
                wire = b"".join(self.enc.encode(cs, self.payload, t_us=10_000 * self.k) for cs in (0, 1))
                self.k += 1
                try:
                    os.write(self.master, wire)
                except OSError:
                    pass

    def close(self) -> None:
        self.stop.set()
        self.thread.join(timeout=5.0)
        if self.master is not None:
            self.unplug()


def test_serial_biotac_comes_back_after_unplug_and_replug(ros_context, tmp_path):
    """Close the pty (unplug), create it again (replug): frames flow again from the first reopen attempt
    after the device returned, the absence is counted, the transport status is OK again, and no
    lifecycle transition was needed."""
    bridge = _Bridge(str(tmp_path / "ttyBioTac"))
    drv, ex, got = _make_biotac(ros_context, {**PARAMS, "transport": "serial", "serial.port": bridge.link_path,
                                              "reconnect_s": 0.25})
    try:
        assert spin_until(ex, lambda: len(got["index"]) >= 3)
        bridge.unplug()
        assert spin_until(ex, lambda: _statuses(drv)["transport"].level == b"\x02")  # ERROR while it is gone
        ex.spin_once(timeout_sec=0.5)  # away for a while: reopen attempts fail meanwhile
        before = len(got["index"])
        back = time.monotonic()
        bridge.replug()
        assert spin_until(ex, lambda: len(got["index"]) > before + 2, timeout_s=30.0)
        recovered_s = time.monotonic() - back
        link = drv.link
        assert link.connected and link.reconnects == 1 and link.disconnects == 1
        # the reopen that worked was the first attempt after the device returned (every reconnect_s)
        assert link.failed_attempts and all(t < back for t in link.failed_attempts), (link.failed_attempts, back)
        assert drv._state_machine.current_state[1] == "active"  # no lifecycle transition was made
        st = _statuses(drv)
        assert st["transport"].level == b"\x00", st["transport"].message  # OK again, by itself
        values = _values(st["transport"])
        assert values["link_reconnects"] == "1" and values["transport_errors"] != "0"
        sensor = _values(st["biotac_index"])
        assert sensor["device_absences"] == "1" and int(sensor["lost_frames"]) >= 40  # >= 0.5 s at 100 Hz
        print(f"recovered {recovered_s:.3f} s after the device returned")
    finally:
        drv.close()
        bridge.close()


def test_bridge_payload_of_another_pattern_is_counted_never_published(ros_context):
    """BioTac SP frames sent to a driver configured for the default pattern: a counted error and a
    WARN, never frames with electrode values in PDC/TAC/TDC."""
    from tactile_descriptors_ros.codecs.biotac_spi import FramePattern
    from tactile_descriptors_ros.codecs.bridge_serial import BridgeEncoder

    drv, ex, got = _make_biotac(ros_context, {**PARAMS, "transport": "loopback", "stamp_source": "device"})
    try:
        enc = BridgeEncoder()
        sp = _payload(FramePattern.parse("biotac_sp"), pdc=3333)
        drv.transport.write(b"".join(enc.encode(1, sp, t_us=10_000 * k) for k in range(20)))
        good = _payload(FramePattern.default(), pdc=2000)
        drv.transport.write(b"".join(enc.encode(1, good, t_us=10_000 * k) for k in range(20, 30)))
        assert spin_until(ex, lambda: len(got["index"]) >= 2)
        pdc = np.concatenate([np.frombuffer(m.pdc, np.uint16) for m in got["index"]])
        assert set(pdc.tolist()) == {2000} and pdc.size == 10
        st = _statuses(drv)["transport"]
        assert _values(st)["payload_decode_errors"] == "20" and st.level == b"\x01"
    finally:
        drv.close()


def test_an_exception_while_handling_a_read_is_counted_and_reading_goes_on(ros_context):
    from tactile_descriptors_ros.codecs.biotac_spi import FramePattern
    from tactile_descriptors_ros.codecs.bridge_serial import BridgeEncoder

    drv, ex, got = _make_biotac(ros_context, {**PARAMS, "transport": "loopback", "stamp_source": "device"})
    try:
        import tactile_descriptors_ros.nodes.biotac_driver as module

        real = module.biotac_batch_to_msg
        calls = {"n": 0}

        def flaky(*args, **kwargs):
            calls["n"] += 1
            if calls["n"] == 1:
                raise RuntimeError("boom while handling")
            return real(*args, **kwargs)

        module.biotac_batch_to_msg = flaky
        enc = BridgeEncoder()
        good = _payload(FramePattern.default())
        drv.transport.write(b"".join(enc.encode(1, good, t_us=10_000 * k) for k in range(5)))
        assert spin_until(ex, lambda: calls["n"] >= 1)
        drv.transport.write(b"".join(enc.encode(1, good, t_us=10_000 * k) for k in range(5, 15)))
        assert spin_until(ex, lambda: len(got["index"]) >= 2)  # the reader lived on
        assert drv._thread is not None and drv._thread.is_alive()
        st = _statuses(drv)["transport"]
        assert _values(st)["consume_errors"] == "1" and "boom" in st.message
    finally:
        module.biotac_batch_to_msg = real
        drv.close()


class _CanQueue:
    """A CAN adapter stand-in that hands over queued frame arrays (with their bus times) read by read,
    each once its newest frame's bus time (``due_ns``, relative to the first read) has passed on the
    host's clock after ``go``: the frames come in real time, as from a bus."""

    name = "can"

    def __init__(self, reads, due_ns) -> None:
        self.reads = list(reads)
        self.due_ns = list(due_ns)
        self.go = threading.Event()
        self.done = threading.Event()
        self.is_open = False
        self._t0: int | None = None

    def open(self) -> None:
        self.is_open = True

    def close(self) -> None:
        self.is_open = False

    def describe(self):
        return {"transport": "queue"}

    def recv_batch(self, max_frames=65536, timeout_s=None):
        from tactile_descriptors_ros.codecs.can_frames import empty_frames

        if self.reads and self.go.is_set():
            if self._t0 is None:
                self._t0 = time.monotonic_ns() - self.due_ns[0]
            wait_s = (self._t0 + self.due_ns[0] - time.monotonic_ns()) / 1e9
            if wait_s > 0:
                time.sleep(min(wait_s, timeout_s or 0.0))
                return empty_frames(0)
            self.due_ns.pop(0)
            return self.reads.pop(0)
        if self.reads:
            self.go.wait(timeout_s or 0.0)
            return empty_frames(0)
        self.done.set()
        time.sleep(timeout_s or 0.0)  # an idle bus: the read times out
        return empty_frames(0)


def test_skin_cell_silent_longer_than_a_wrap_keeps_its_stamps(ros_context):
    """A NAO cell silent for 200 ms, then 300 ms (8-bit numbers wrap every 256 ms at 1 kHz): published
    accelerometer times are the sample times plus the clock offset, which moves only by what the
    reads' delays teach it (never by a 256 or 512 ms wrap, never a step back), and the body part's
    lost frames are those of the silences, as the bus counts them."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter

    from tactile_descriptors_msgs.msg import SkinPartFrames
    from tactile_descriptors_ros.codecs.skin import Modality, SkinSampleBatch
    from tactile_descriptors_ros.codecs.skin_can import encode_can_frames
    from tactile_descriptors_ros.core.robot import load_robot
    from tactile_descriptors_ros.nodes.skin_driver import SkinDriver

    part = load_robot("nao").body_part("left_hand")
    cell = part.cells[0].id
    t0, ms_ns = 1_700_000_000 * 10**9, 1_000_000
    silent = [(300, 500), (700, 1000)]
    rows = []
    for ms in range(1300):
        if any(a <= ms < b for a, b in silent):
            continue
        rows.append((int(Modality.ACCEL), ms % 256, ms))
        if ms % 4 == 0:
            rows.append((int(Modality.FORCE), (ms // 4) % 256, ms))
    n = len(rows)
    ms = np.array([r[2] for r in rows], np.int64)
    batch = SkinSampleBatch(np.full(n, cell, np.int64), np.array([r[0] for r in rows], np.int64),
                            np.array([r[1] for r in rows], np.int64), np.tile([1, 2, 3], (n, 1)).astype(np.int64),
                            t0 + ms * ms_ns)
    frames = encode_can_frames(batch)
    sel = [(ms >= a) & (ms < a + 10) for a in range(0, 1300, 10)]
    can = _CanQueue([frames[m] for m in sel if m.any()], [int(ms[m].max()) * ms_ns for m in sel if m.any()])
    drv = SkinDriver(context=ros_context, transport_factory=lambda node: can,
                     parameter_overrides=[Parameter(k, value=v) for k, v in {
                         "robot": "nao", "body_parts": ["left_hand"], "transport": "can", "tare_on_start_s": 0.0,
                         "resync_s": 0.0, "stamp_source": "clock"}.items()])
    sink = rclpy.create_node("sink", context=ros_context)
    got = []
    sink.create_subscription(SkinPartFrames, "tactile/left_hand/frames", got.append, 1000)
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(drv)
    ex.add_node(sink)
    try:
        assert spin_until(ex, lambda: drv.part_publishers["left_hand"].get_subscription_count() > 0)
        started_ns = time.time_ns()
        can.go.set()
        assert spin_until(ex, lambda: can.done.is_set() and sum(len(m.accel_offset_ns) for m in got) >= 750,
                          timeout_s=60.0)
        mine = cell_runs(got, cell)
        stamps = np.concatenate([f.stamp_ns + f.accel_offset_ns for _, f, _ in mine])
        assert stamps.size >= 750
        step = np.diff(stamps)
        assert np.all(step > 0)
        # the silences are holes of their own length (a wrong unwrap would add or take 256 ms); a step of
        # the offset (a read with a smaller delay than any before) moves a stamp by milliseconds at most
        holes = step[step > 20 * ms_ns]
        assert holes.size == 2 and np.all(np.abs(holes - np.array([201, 301]) * ms_ns) < 30 * ms_ns), holes / ms_ns
        assert started_ns - 1_000 * ms_ns < stamps[0] and stamps[-1] <= time.time_ns()  # on the host clock
        lost = 200 + 300 + 50 + 75  # accelerometer and force frames of the silences
        assert drv.decoder.stats.lost_frames == lost and drv.decoder.stats.sequence_resets == 0
        assert int(_values(_statuses(drv)["left_hand"])["lost_frames"]) == lost
    finally:
        drv.close()


class _CanAdapter:
    """A USB-CAN adapter that can be unplugged: the python-can bus of :class:`UnpluggableCanBus`.

    ``deliver`` puts frames on the open bus as the adapter receives them (stamped with the host time); a
    frame that arrives while the adapter is unplugged, or plugged in but not opened yet, is received by
    nobody (``never_received``).  ``unplug`` makes every read and every open fail, as a vanished network
    interface does, and drops the frames the driver had not read yet (``dropped``).  ``replug`` makes
    the device openable again; the handle opened before stays dead.
    """

    adapters: dict[str, _CanAdapter] = {}

    def __init__(self, channel: str) -> None:
        import queue

        self.channel = channel
        self.lock = threading.Lock()
        self.plugged = True
        self.generation = 0
        self.queue: queue.SimpleQueue | None = None
        self.never_received = 0
        self.dropped = 0
        self.opens = 0
        _CanAdapter.adapters[channel] = self

    def deliver(self, messages) -> None:
        now = time.time()
        with self.lock:
            if not self.plugged or self.queue is None:
                self.never_received += len(messages)
                return
            for msg in messages:
                msg.timestamp = now
                self.queue.put(msg)

    def unplug(self) -> None:
        with self.lock:
            self.plugged = False
            if self.queue is not None:
                self.dropped += self.queue.qsize()
                self.queue = None

    def replug(self) -> None:
        with self.lock:
            self.plugged = True
            self.generation += 1


try:
    import can as _can
except ImportError:  # pragma: no cover - python-can is a dependency
    _can = None

if _can is not None:
    class UnpluggableCanBus(_can.BusABC):
        """python-can interface ``tactile_test_unpluggable`` over :class:`_CanAdapter` (channel = adapter)."""

        def __init__(self, channel, **kwargs) -> None:
            import queue

            adapter = _CanAdapter.adapters.get(str(channel))
            if adapter is None:
                raise _can.CanInitializationError(f"{channel}: no such device")
            with adapter.lock:
                if not adapter.plugged:
                    raise _can.CanInitializationError(f"{channel}: No such device")
                adapter.queue = self._queue = queue.SimpleQueue()
                adapter.opens += 1
                self._generation = adapter.generation
            self._adapter = adapter
            self.channel_info = f"unpluggable {channel}"
            super().__init__(channel=channel, **kwargs)

        def _alive(self) -> bool:
            a = self._adapter
            return a.plugged and a.generation == self._generation and a.queue is self._queue

        def _recv_internal(self, timeout):
            import queue

            deadline = time.monotonic() + (timeout or 0.0)
            while True:
                with self._adapter.lock:
                    if not self._alive():
                        raise _can.CanOperationError(f"{self.channel_info}: Network is down")
                    try:
                        return self._queue.get_nowait(), False
                    except queue.Empty:
                        pass
                if time.monotonic() >= deadline:
                    return None, False
                time.sleep(0.001)

        def send(self, msg, timeout=None) -> None:
            raise _can.CanOperationError("this adapter only receives")

        def shutdown(self) -> None:
            with self._adapter.lock:
                if self._adapter.queue is self._queue:
                    self._adapter.queue = None
            super().shutdown()


class _SkinCell:
    """One NAO skin cell on the adapter, sampling at 1 kHz (accelerometer) and 250 Hz (force) in real time
    from a thread, whether or not the adapter is plugged in (its numbers run on while unplugged)."""

    def __init__(self, adapter: _CanAdapter, cell_id: int) -> None:
        from tactile_descriptors_ros.codecs.skin_can import SkinCanEncoder

        self.adapter, self.cell_id = adapter, cell_id
        self.enc = SkinCanEncoder()
        self.k = 0
        self.stop = threading.Event()
        self.t0 = time.monotonic()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        from tactile_descriptors_ros.codecs.skin import Modality

        while not self.stop.wait(0.005):
            due = int((time.monotonic() - self.t0) * 1000)
            msgs = []
            while self.k < due:
                msgs.append(self.enc.encode(self.cell_id, Modality.ACCEL, (self.k % 50 - 25, 3, -4)))
                if self.k % 4 == 0:
                    msgs.append(self.enc.encode(self.cell_id, Modality.FORCE, (100, 110, 120)))
                self.k += 1
            self.adapter.deliver(msgs)

    def close(self) -> None:
        self.stop.set()
        self.thread.join(timeout=5.0)


def test_can_skin_driver_comes_back_after_the_adapter_is_unplugged_and_replugged(ros_context, monkeypatch):
    """The CAN adapter vanishes (every read fails with an interface error, opening fails) and comes back:
    the driver reads again from the first reopen attempt after the adapter returned, with no lifecycle
    transition; the absence is counted (link disconnects and reconnects, the time away) and the frames
    the cell sent meanwhile are the body part's lost frames, exactly; the bus status is OK again."""
    import can.interfaces
    import can.util
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter

    from tactile_descriptors_ros.nodes.skin_driver import SkinDriver

    # a python-can interface of its own, registered as a plugin package registers one
    monkeypatch.setitem(can.interfaces.BACKENDS, "tactile_test_unpluggable", (__name__, "UnpluggableCanBus"))
    monkeypatch.setattr(can.util, "VALID_INTERFACES", can.util.VALID_INTERFACES | {"tactile_test_unpluggable"})
    channel = f"usbcan_{time.monotonic_ns()}"
    adapter = _CanAdapter(channel)
    cell_id = 1
    drv = SkinDriver(context=ros_context, parameter_overrides=[Parameter(k, value=v) for k, v in {
        "robot": "nao", "body_parts": ["left_hand"], "transport": "can", "can.interface": "tactile_test_unpluggable",
        "can.channel": channel, "tare_on_start_s": 0.0, "resync_s": 0.0, "reconnect_s": 0.25}.items()])
    pub = drv.part_publishers["left_hand"]
    sink = rclpy.create_node("sink", context=ros_context)
    got = []
    sink.create_subscription(pub.msg_type, pub.topic_name, got.append, 1000)
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(drv)
    ex.add_node(sink)
    cell = None
    try:
        assert spin_until(ex, lambda: pub.get_subscription_count() > 0)
        cell = _SkinCell(adapter, cell_id)
        assert spin_until(ex, lambda: len(got) >= 3)
        adapter.unplug()
        assert spin_until(ex, lambda: _statuses(drv)["bus"].level == b"\x02")  # ERROR while it is gone
        assert "reopening" in _statuses(drv)["bus"].message
        link = drv.link
        assert spin_until(ex, lambda: link.reopen_failures >= 2)  # away for a while: reopening fails meanwhile
        before = len(got)
        back = time.monotonic()
        adapter.replug()
        assert spin_until(ex, lambda: len(got) > before + 2, timeout_s=30.0)
        recovered_s = time.monotonic() - back
        assert link.connected and link.reconnects == 1 and link.disconnects == 1 and adapter.opens == 2
        # the reopen that worked was the first attempt after the adapter returned (one every reconnect_s)
        assert link.failed_attempts and all(t < back for t in link.failed_attempts), (link.failed_attempts, back)
        assert link.last_gap_s >= 2 * drv.reconnect_s  # the time away, reported (two reopens failed)
        assert drv._state_machine.current_state[1] == "active"  # no lifecycle transition was made
        st = _statuses(drv)
        assert st["bus"].level == b"\x00", st["bus"].message  # OK again, by itself
        values = _values(st["bus"])
        assert values["link_reconnects"] == "1" and values["link_disconnects"] == "1"
        assert values["transport_errors"] != "0" and float(values["link_last_gap_s"]) == round(link.last_gap_s, 3)
        # every frame the cell sent while the driver could not read it is counted lost, no more, no less
        missed = adapter.never_received + adapter.dropped
        assert missed > 0
        assert spin_until(ex, lambda: drv.cells[cell_id].lost == missed)
        assert drv.decoder.stats.lost_frames == missed and drv.decoder.stats.sequence_resets == 0
        assert spin_until(ex, lambda: int(_values(_statuses(drv)["left_hand"])["lost_frames"]) == missed)
        print(f"recovered {recovered_s:.3f} s after the adapter returned; away {link.last_gap_s:.3f} s, "
              f"{missed} frames lost")
    finally:
        if cell is not None:
            cell.close()
        drv.close()
