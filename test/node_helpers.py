"""Shared helpers of the node tests: synthetic BioTac batches and spinning with a deadline."""

from __future__ import annotations

import time

import numpy as np


def spin_until(executor, cond, timeout_s: float = 10.0) -> bool:
    """Spin ``executor`` until ``cond()`` or the timeout; return ``cond()``."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and not cond():
        executor.spin_once(timeout_sec=0.02)
    return bool(cond())


class BiotacStream:
    """Consecutive synthetic BioTac batches of one finger: a sine of ``freq_hz`` on PAC, force from PDC."""

    def __init__(self, sensor_name="biotac_index", body_part="index", seed=0) -> None:
        self.sensor_name, self.body_part = sensor_name, body_part
        self.rng = np.random.default_rng(seed)
        self.t_ns = 1_000_000_000
        self.seq = 0

    def batch(self, force_n: float, freq_hz: float, n_frames: int = 10):
        from tactile_descriptors_ros.nodes.conversions import biotac_batch_to_msg
        from tactile_descriptors_ros.streams.frames import BioTacBatch

        fo = np.arange(n_frames, dtype=np.int64) * 10_000_000
        po = np.arange(n_frames * 22, dtype=np.int64) * (10_000_000 // 22)
        t = (self.t_ns + po) / 1e9
        pac = (2000 + 300 * np.sin(2 * np.pi * freq_hz * t) + self.rng.normal(0, 30, po.size)).astype(np.uint16)
        pdc = np.full(n_frames, 1000 + force_n / 0.05, np.uint16)
        el = (1500 + self.rng.normal(0, 20, (n_frames, 19)) + force_n * 40).astype(np.uint16)
        b = BioTacBatch(self.t_ns, pac, po, fo, pdc, pdc, pdc, el, self.seq)
        self.t_ns += n_frames * 10_000_000
        self.seq += n_frames
        return biotac_batch_to_msg(b, sensor_name=self.sensor_name, body_part=self.body_part, chip_select=1,
                                   force_n_per_count=0.05, pdc_tare_counts=1000.0)

    def exploration(self, freq_hz: float, touch_batches: int = 25, release_batches: int = 4):
        """Messages of one touch (2.5 s at 2 N) and release."""
        return [self.batch(2.0, freq_hz) for _ in range(touch_batches)] + \
               [self.batch(0.0, freq_hz) for _ in range(release_batches)]


def cell_runs(messages, cell_id: int | None = None) -> list:
    """The cell runs of received ``SkinPartFrames``: ``(cell_id, SkinFrame, tare)`` in arrival order.

    With ``cell_id``, only that cell's runs.
    """
    from tactile_descriptors_ros.nodes.conversions import skin_part_from_msg

    out = []
    for msg in messages:
        out += [r for r in skin_part_from_msg(msg).frames() if cell_id is None or r[0] == cell_id]
    return out


def left_hand_fixed_parameters() -> list:
    """Window node parameters of the NAO's left hand in fixed 0.5 s windows every 0.25 s, no lateness, frames
    taken reliably from a deep queue (:func:`window_nodes_side_by_side`'s ``common``)."""
    from rclpy.parameter import Parameter

    return [Parameter("robot", value="nao"), Parameter("body_parts", value=["left_hand"]),
            Parameter("window.mode", value="fixed"), Parameter("window.length_s", value=0.5),
            Parameter("window.hop_s", value=0.25), Parameter("window.lateness_s", value=0.0),
            Parameter("qos.frames.reliability", value="reliable"), Parameter("qos.frames.depth", value=2000)]


def window_nodes_side_by_side(ros_context, common: list, variants: dict[str, list]):
    """Window nodes fed the same ``SkinPartFrames`` of the NAO's left hand, one per variant, and an ``io`` node.

    Node ``wn_<name>`` takes ``common`` plus its variant's parameters and publishes its descriptors on
    ``desc_<name>``; ``io`` publishes the frames (reliable, depth 2000) on ``tactile/left_hand/frames`` and
    collects each node's descriptors in ``out["desc_<name>"]``.  Returns ``(nodes, io, pub, out, executor)``
    once every node's subscription has matched the publisher.
    """
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from tactile_descriptors_msgs.msg import Descriptor, SkinPartFrames
    from tactile_descriptors_ros.nodes.window_node import WindowNode

    nodes = {name: WindowNode(f"wn_{name}", context=ros_context, parameter_overrides=[*common, *extra],
                              cli_args=["--ros-args", "-r", f"tactile/descriptor:=desc_{name}"])
             for name, extra in variants.items()}
    io = rclpy.create_node("io", context=ros_context)
    pub = io.create_publisher(SkinPartFrames, "tactile/left_hand/frames",
                              QoSProfile(depth=2000, reliability=ReliabilityPolicy.RELIABLE))
    out = {f"desc_{name}": [] for name in variants}
    for topic, got in out.items():
        io.create_subscription(Descriptor, topic, got.append, 50)
    ex = SingleThreadedExecutor(context=ros_context)
    for n in (*nodes.values(), io):
        ex.add_node(n)
    assert spin_until(ex, lambda: pub.get_subscription_count() >= len(nodes), 10)
    return nodes, io, pub, out, ex
