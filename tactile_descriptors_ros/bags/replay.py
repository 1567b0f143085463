"""Play a bag onto live topics with its original timing (``tactile replay``).

* Each message is published, as the raw CDR bytes in the bag, when
  ``(t - t_start) / rate`` of wall time has passed since the start.
* ``/clock`` (``rosgraph_msgs/Clock``): before every message the clock is set
  to that message's log time, and between messages it ticks at
  ``clock_rate_hz`` (bag time), so nodes running with ``use_sim_time`` see
  the recorded time line, never a message from their future.
* Each topic's publisher offers the QoS adapted from the bag's
  ``offered_qos_profiles`` (reliability, durability, history and depth; see
  :mod:`.qos`); ``qos_overrides`` replaces it per topic.
* ``loop`` starts again from the beginning; like ``ros2 bag play --loop``
  the clock then jumps back to the bag's start.
* Topics whose message type is not installed here are skipped and reported
  (rclpy needs the type support even to publish raw bytes).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from rosbags.interfaces import Qos

from ..errors import BagError
from ..launching.signals import SignalStop
from .io import BagReader
from .live import message_class
from .qos import DEFAULT_DEPTH, adapt_offered_qos, qos_to_dict, qos_to_rclpy

__all__ = ["PlayOptions", "PlayReport", "Player", "play"]


@dataclass(frozen=True)
class PlayOptions:
    """How to play a bag.

    Attributes
    ----------
    rate : float
        Speed factor (2.0 = twice as fast).
    start_offset_s : float
        Skip this much of the bag's beginning.
    loop : bool
    topics : tuple of str or None
        Only these topics (default: all).
    clock : bool
        Publish ``/clock`` (off by default, as in ``ros2 bag play``).
    clock_rate_hz : float
        Clock ticks per second of bag time between messages (0: only at messages).
    wait_for_subscribers_s : float
        Before starting, wait up to this long until every topic has a subscriber.
    delay_s : float
        Wall time to wait before the first message (after discovery).
    remap : mapping of str to str
        Bag topic -> live topic.
    qos_overrides : mapping of str to Qos
        Bag topic -> profile to offer instead of the adapted one.
    default_depth : int
        Depth when the bag's offers carry none.
    """

    rate: float = 1.0
    start_offset_s: float = 0.0
    loop: bool = False
    topics: tuple[str, ...] | None = None
    clock: bool = False
    clock_rate_hz: float = 100.0
    wait_for_subscribers_s: float = 0.0
    delay_s: float = 0.0
    remap: Mapping[str, str] = field(default_factory=dict)
    qos_overrides: Mapping[str, Qos] = field(default_factory=dict)
    default_depth: int = DEFAULT_DEPTH

    def validate(self) -> None:
        if not self.rate > 0:
            raise BagError(f"rate must be positive, not {self.rate}")
        if self.start_offset_s < 0:
            raise BagError("start offset must not be negative")
        if self.clock_rate_hz < 0:
            raise BagError("clock rate must not be negative")


@dataclass
class PlayReport:
    """What a replay published."""

    bag: str
    published: dict[str, int] = field(default_factory=dict)
    qos: dict[str, dict[str, Any]] = field(default_factory=dict)
    skipped: dict[str, str] = field(default_factory=dict)
    clock_messages: int = 0
    loops: int = 0
    wall_s: float = 0.0
    max_lag_s: float = 0.0
    interrupted: bool = False

    @property
    def message_count(self) -> int:
        return sum(self.published.values())

    def to_dict(self) -> dict[str, Any]:
        return {
            "bag": self.bag,
            "message_count": self.message_count,
            "published": dict(self.published),
            "qos": dict(self.qos),
            "skipped": dict(self.skipped),
            "clock_messages": self.clock_messages,
            "loops": self.loops,
            "wall_s": self.wall_s,
            "max_lag_s": self.max_lag_s,
            "interrupted": self.interrupted,
        }


class Player:
    """Publishes a bag's messages on live topics; one rclpy node.

    Parameters
    ----------
    bag_path : path
    options : PlayOptions
    context : rclpy.Context, optional
    node_name : str
    """

    def __init__(self, bag_path: str, options: PlayOptions | None = None, context: Any = None,
                 node_name: str = "tactile_player") -> None:
        from rclpy.node import Node
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from rosgraph_msgs.msg import Clock

        self.options = options or PlayOptions()
        self.options.validate()
        self.bag_path = str(bag_path)
        self.reader = BagReader(bag_path).open()
        info = self.reader.info
        assert info is not None
        self.info = info
        wanted = set(self.options.topics) if self.options.topics is not None else set(info.topics)
        unknown = wanted - set(info.topics)
        if unknown:
            self.reader.close()
            raise BagError(f"{bag_path}: no topic {', '.join(sorted(unknown))} in the bag "
                           f"(has: {', '.join(sorted(info.topics))})")
        self.node = Node(node_name, context=context)
        self.report = PlayReport(bag=self.bag_path)
        self.publishers: dict[str, Any] = {}
        for topic in sorted(wanted):
            t = info.topics[topic]
            try:
                cls = message_class(t.msgtype)
            except BagError as exc:
                self.report.skipped[topic] = str(exc)
                self.node.get_logger().warning(f"skipping {topic}: {exc}")
                continue
            qos = self.options.qos_overrides.get(topic) or adapt_offered_qos(t.offered_qos, self.options.default_depth)
            live = self.options.remap.get(topic, topic)
            self.publishers[topic] = self.node.create_publisher(cls, live, qos_to_rclpy(qos, self.options.default_depth))
            self.report.published[topic] = 0
            self.report.qos[topic] = qos_to_dict(qos)
        self._clock_cls = Clock
        self._clock_pub = None
        if self.options.clock:
            # rclpy/rclcpp subscribe to /clock best effort, depth 1; a reliable offer matches them too.
            self._clock_pub = self.node.create_publisher(
                Clock, "/clock", QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE)
            )

    # ------------------------------------------------------------------ helpers
    def _publish_clock(self, t_ns: int) -> None:
        if self._clock_pub is None:
            return
        msg = self._clock_cls()
        msg.clock.sec = int(t_ns // 1_000_000_000)
        msg.clock.nanosec = int(t_ns % 1_000_000_000)
        self._clock_pub.publish(msg)
        self.report.clock_messages += 1

    def wait_for_subscribers(self, timeout_s: float) -> bool:
        """Wait until every publisher has at least one subscription; False on timeout."""
        deadline = time.monotonic() + timeout_s
        while True:
            if all(p.get_subscription_count() > 0 for p in self.publishers.values()):
                return True
            if time.monotonic() >= deadline:
                return False
            time.sleep(0.02)

    def _sleep_until(self, wall_target: float, wall0: float, bag0_ns: int, next_ns: int,
                     stop: threading.Event | SignalStop | None) -> bool:
        """Sleep until ``wall_target``, ticking the clock; False if stopped."""
        opts = self.options
        tick_wall = (1.0 / opts.clock_rate_hz) / opts.rate if (self._clock_pub and opts.clock_rate_hz > 0) else None
        while True:
            if stop is not None and stop.is_set():
                return False
            if not self.node.context.ok():
                return False
            now = time.monotonic()
            remaining = wall_target - now
            if remaining <= 0:
                return True
            if tick_wall is not None and remaining > tick_wall:
                time.sleep(tick_wall)
                bag_now = bag0_ns + int((time.monotonic() - wall0) * opts.rate * 1e9)
                self._publish_clock(min(bag_now, next_ns))
            else:
                time.sleep(min(remaining, 0.05))

    # ------------------------------------------------------------------ running
    def play(self, stop: threading.Event | SignalStop | None = None) -> PlayReport:
        """Play (looping if asked) until the end, ``stop`` is set, or the context shuts down."""
        opts = self.options
        started = time.monotonic()
        if opts.wait_for_subscribers_s > 0 and not self.wait_for_subscribers(opts.wait_for_subscribers_s):
            missing = [t for t, p in self.publishers.items() if p.get_subscription_count() == 0]
            self.node.get_logger().warning(f"no subscriber yet on {', '.join(missing)}; playing anyway")
        if opts.delay_s > 0:
            time.sleep(opts.delay_s)
        start_ns = self.info.start_ns + int(round(opts.start_offset_s * 1e9))
        topics = list(self.publishers)
        try:
            while True:
                wall0 = time.monotonic()
                self._publish_clock(start_ns)
                finished = True
                for msg in self.reader.messages(topics, start_ns=start_ns):
                    target = wall0 + (msg.log_time_ns - start_ns) / 1e9 / opts.rate
                    if not self._sleep_until(target, wall0, start_ns, msg.log_time_ns, stop):
                        finished = False
                        break
                    self.report.max_lag_s = max(self.report.max_lag_s, time.monotonic() - target)
                    self._publish_clock(msg.log_time_ns)
                    self.publishers[msg.topic].publish(msg.data)
                    self.report.published[msg.topic] += 1
                self.report.loops += 1
                if not finished:
                    self.report.interrupted = True
                    break
                if not opts.loop:
                    break
        except KeyboardInterrupt:
            self.report.interrupted = True
            raise
        finally:
            self.report.wall_s = time.monotonic() - started
        return self.report

    def play_paced(self, before: Callable[[Any], bool]) -> PlayReport:
        """Publish every message once, in bag order, paced by the caller instead of the clock.

        ``before(message)`` is called with each :class:`~.io.BagMessage` before it is
        published and may block until the graph has taken what came before (a
        descriptor, a prediction); it returns False to stop.  No wall-clock
        pacing, no ``/clock``: for replays whose consumers signal their progress
        (``tactile evaluate --live``), so that a slow machine changes the wall
        time, never what is received.
        """
        started = time.monotonic()
        try:
            for msg in self.reader.messages(list(self.publishers)):
                if not before(msg):
                    self.report.interrupted = True
                    break
                self.publishers[msg.topic].publish(msg.data)
                self.report.published[msg.topic] += 1
            self.report.loops += 1
        finally:
            self.report.wall_s = time.monotonic() - started
        return self.report

    def destroy(self) -> None:
        """Close the bag and destroy the node."""
        self.reader.close()
        self.node.destroy_node()


def play(bag_path: str, options: PlayOptions | None = None, context: Any = None,
         stop: threading.Event | SignalStop | None = None) -> PlayReport:
    """Play a bag once (or looping) and return what was published."""
    player = Player(bag_path, options, context=context)
    try:
        return player.play(stop)
    finally:
        player.destroy()

