"""Driver stamps through real topics: no sample is stamped after the message carrying it was received.

The drivers run the simulated transports at real time with ``clock`` stamps
(the shipped default), a subscriber notes the host time at which each
message arrives, and every sample stamp of every message must be at or
before it, from the start, after a lifecycle reconfigure with 0.6 s between
configure and activate (frames buffer meanwhile and are read at once) and
after a replug.  ``header.stamp`` (the oldest sample) is then a small
positive delay, what ``ros2 topic delay`` shows.
"""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest
from node_helpers import spin_until

pytestmark = pytest.mark.ros


def _stamp_ns(stamp) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


#: every sample-time field of the two frames messages (a message may carry one modality only: seen once in
#: CI on Jazzy, a skin message after the replug with force samples and no accelerometer sample)
OFFSET_FIELDS = ("accel_offset_ns", "force_offset_ns", "pac_offset_ns", "frame_offset_ns")


def _newest_sample_ns(msg) -> int | None:
    """Stamp of the message's newest sample of any modality (None for a message without samples)."""
    newest = [int(max(o)) for o in (getattr(msg, f, ()) for f in OFFSET_FIELDS) if len(o)]
    return _stamp_ns(msg.header.stamp) + max(newest) if newest else None


def _spin_for(ex, seconds: float) -> None:
    """Run the graph for ``seconds`` (the scenario's own pause, not a wait for an event)."""
    end = time.monotonic() + seconds
    spin_until(ex, lambda: time.monotonic() >= end, timeout_s=seconds + 1.0)


class _Unpluggable:
    """The simulated transport, whose next read fails once ``unplug`` is set (the reader thread sees the
    device go; the driver reopens a fresh one, whose scene and device clock start again)."""

    def __init__(self, inner, unplug: threading.Event) -> None:
        self.inner = inner
        self.unplug = unplug

    def __getattr__(self, name):
        return getattr(self.inner, name)

    def _check(self) -> None:
        from tactile_descriptors_ros.errors import TransportError

        if self.unplug.is_set():
            self.unplug.clear()
            raise TransportError("unplugged by the test")

    def read(self, *args, **kwargs):
        self._check()
        return self.inner.read(*args, **kwargs)

    def recv_batch(self, *args, **kwargs):
        self._check()
        return self.inner.recv_batch(*args, **kwargs)


def _driver(ros_context, kind: str):
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter

    if kind == "biotac":
        from tactile_descriptors_msgs.msg import BioTacFrameBatch as Msg
        from tactile_descriptors_ros.nodes.biotac_driver import BiotacDriver as Driver
        params = {"robot": "shadow_hand", "body_parts": ["index"], "transport": "simulated",
                  "sim.scene": "demo_shadow_hand", "tare_on_start_s": 0.0}
        topic = "tactile/index/frames"
    else:
        from tactile_descriptors_msgs.msg import SkinPartFrames as Msg
        from tactile_descriptors_ros.nodes.skin_driver import SkinDriver as Driver
        params = {"robot": "nao", "body_parts": ["left_hand"], "transport": "simulated", "sim.scene": "demo_nao",
                  "tare_on_start_s": 0.0, "batch_s": 0.01}
        topic = "tactile/left_hand/frames"
    from tactile_descriptors_ros.transports import create_transport

    unplug = threading.Event()
    drv = Driver(context=ros_context, parameter_overrides=[Parameter(k, value=v) for k, v in params.items()],
                 transport_factory=lambda node: _Unpluggable(
                     create_transport("simulated", source=node._simulated_source()), unplug))
    drv.unplug = unplug
    if kind == "skin":  # a read keeps the whole 0.6 s reconfigure backlog below (shedding: test_drain_frames)
        drv.max_read_frames = 1 << 20
    sink = rclpy.create_node("stamp_sink", context=ros_context)
    got: list[tuple[int, int, int | None]] = []  # (receive host ns, header stamp ns, newest sample ns)

    def on_msg(msg) -> None:
        got.append((time.time_ns(), _stamp_ns(msg.header.stamp), _newest_sample_ns(msg)))

    sink.create_subscription(Msg, topic, on_msg, 500)
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(drv)
    ex.add_node(sink)
    return drv, ex, got


@pytest.mark.parametrize("kind", ["biotac", "skin"])
def test_no_sample_is_stamped_after_its_message_arrived(ros_context, kind):
    drv, ex, got = _driver(ros_context, kind)
    try:
        assert spin_until(ex, lambda: len(got) >= 20, timeout_s=60.0)
        # a lifecycle reconfigure with 0.6 s between configure and activate: the frames of that time are
        # read at once by the first read (the stamps used to anchor the oldest of them at "now")
        drv.trigger_deactivate()
        drv.trigger_cleanup()
        drv.trigger_configure()
        _spin_for(ex, 0.6)
        before = len(got)
        drv.trigger_activate()
        assert spin_until(ex, lambda: len(got) >= before + 20, timeout_s=60.0)
        # a replug: the device gone and back
        after_reconfigure = len(got)
        reconnects = drv.link.reconnects
        drv.unplug.set()
        assert spin_until(ex, lambda: drv.link.reconnects > reconnects, timeout_s=30.0)
        assert spin_until(ex, lambda: len(got) >= after_reconfigure + 20, timeout_s=60.0)
    finally:
        drv.close()
    with_samples = np.array([(r, n) for r, _, n in got if n is not None], dtype=np.int64)
    assert len(with_samples) >= 60, f"only {len(with_samples)} of {len(got)} messages carried samples"
    assert np.all(with_samples[:, 1] <= with_samples[:, 0]), (with_samples[:, 0] - with_samples[:, 1]).min()
    arr = np.array([(r, h) for r, h, _ in got], dtype=np.int64)
    receive, header = arr[:, 0], arr[:, 1]
    delay_s = (receive - header) / 1e9
    assert np.all(delay_s > 0)
    # the reconfigure's backlog is stamped at its own times: its oldest message is about 0.6 s old
    assert delay_s[before] > 0.5
