"""Record live topics into a bag, bytes exactly as received (``tactile record``).

A :class:`Recorder` owns one rclpy node.  Every ``discovery_period_s`` it
looks at the graph and subscribes, with raw subscriptions, to each selected
topic that has at least one publisher; the subscription's QoS is adapted to
the publishers' offers (reliable only if all are, transient local only if all
are; see :mod:`.qos`) and the offers are stored in the bag as
``offered_qos_profiles`` so that a replay offers the same.  Messages are
written with the receive time of the node's clock (ROS time, or ``/clock``
under ``use_sim_time``) as log time.

Publishers that appear after a topic was subscribed are received but their
QoS is not added to the bag; a topic whose publishers use different types is
refused and reported.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from ..errors import BagError
from ..launching.signals import SignalStop
from .io import BagWriter
from .live import TopicSelector, message_class, publisher_offers, subscription_qos_for

__all__ = ["RecordReport", "Recorder", "record"]


@dataclass
class RecordReport:
    """What a recording took."""

    bag: str
    messages: dict[str, int] = field(default_factory=dict)
    types: dict[str, str] = field(default_factory=dict)
    refused: dict[str, str] = field(default_factory=dict)
    duration_s: float = 0.0

    @property
    def message_count(self) -> int:
        return sum(self.messages.values())

    def to_dict(self) -> dict[str, Any]:
        return {
            "bag": self.bag,
            "duration_s": self.duration_s,
            "message_count": self.message_count,
            "messages": dict(self.messages),
            "types": dict(self.types),
            "refused": dict(self.refused),
        }


class Recorder:
    """Subscribe to selected topics and write what arrives into ``writer``.

    Parameters
    ----------
    writer : BagWriter
        An open bag writer, used only from the thread that calls :meth:`spin`
        (the thread that opened it: sqlite3 connections are bound to it).
    selector : TopicSelector
        Which topics to record.
    context : rclpy.Context, optional
        Default: the global context (``rclpy.init()`` must have been called).
    node_name : str
    depth : int
        Subscription history depth (large, so bursts are not dropped).
    discovery_period_s : float
        How often the graph is checked for new topics.
    use_sim_time : bool
        Log times from ``/clock`` instead of the system clock.
    """

    def __init__(self, writer: BagWriter, selector: TopicSelector, context: Any = None,
                 node_name: str = "tactile_recorder", depth: int = 100, discovery_period_s: float = 0.2,
                 use_sim_time: bool = False) -> None:
        from rclpy.node import Node
        from rclpy.parameter import Parameter

        self.writer = writer
        self.selector = selector
        self.depth = depth
        self.node = Node(node_name, context=context,
                         parameter_overrides=[Parameter("use_sim_time", value=use_sim_time)])
        self._context = context
        self._subscriptions: dict[str, Any] = {}
        self._lock = threading.Lock()
        self.report = RecordReport(bag=str(writer.path))
        self._timer = self.node.create_timer(discovery_period_s, self.discover)

    # ------------------------------------------------------------------ graph
    def discover(self) -> list[str]:
        """Subscribe to newly seen selected topics that have publishers; returns the new ones."""
        new = []
        own = self.node.get_fully_qualified_name()
        for topic, types in self.node.get_topic_names_and_types():
            if topic in self._subscriptions or topic in self.report.refused or not self.selector(topic):
                continue
            infos = [i for i in self.node.get_publishers_info_by_topic(topic)
                     if f"{i.node_namespace.rstrip('/')}/{i.node_name}" != own]
            if not infos:
                continue  # wait for a publisher: its QoS decides ours
            if len(types) != 1:
                self._refuse(topic, f"published with several types {types}")
                continue
            msgtype = types[0]
            try:
                cls = message_class(msgtype)
                offers = publisher_offers(self.node, topic)
                self.writer.add_topic(topic, msgtype, offers)
            except BagError as exc:
                self._refuse(topic, str(exc))
                continue
            qos = subscription_qos_for(offers, self.depth)
            self._subscriptions[topic] = self.node.create_subscription(
                cls, topic, self._make_callback(topic), qos, raw=True
            )
            self.report.types[topic] = msgtype
            self.report.messages.setdefault(topic, 0)
            new.append(topic)
        return new

    def _refuse(self, topic: str, why: str) -> None:
        self.report.refused[topic] = why
        self.node.get_logger().warning(f"not recording {topic}: {why}")

    def _make_callback(self, topic: str):
        clock = self.node.get_clock()

        def on_message(data: bytes) -> None:
            t_ns = clock.now().nanoseconds
            with self._lock:
                self.writer.write(topic, t_ns, data)
                self.report.messages[topic] += 1

        return on_message

    @property
    def topics(self) -> list[str]:
        return sorted(self._subscriptions)

    # ------------------------------------------------------------------ running
    def spin(self, duration_s: float | None = None, stop: threading.Event | SignalStop | None = None,
             max_messages: int | None = None) -> RecordReport:
        """Record until ``duration_s`` passed, ``stop`` is set, ``max_messages`` arrived, or shutdown.

        On a stop (not Ctrl-C's exception) the messages already received are
        written before returning, so a message acknowledged to a reliable
        publisher before the stop is in the bag.

        Ctrl-C (``KeyboardInterrupt``) propagates after the report is updated;
        the caller's ``BagWriter`` context then closes the bag cleanly.
        """
        from rclpy.executors import SingleThreadedExecutor

        executor = SingleThreadedExecutor(context=self._context)
        executor.add_node(self.node)
        start = time.monotonic()
        self.discover()
        try:
            while self.node.context.ok():
                if stop is not None and stop.is_set():
                    break
                if duration_s is not None and time.monotonic() - start >= duration_s:
                    break
                if max_messages is not None and self.report.message_count >= max_messages:
                    break
                executor.spin_once(timeout_sec=0.05)
            self._drain()
        finally:
            self.report.duration_s = time.monotonic() - start
            executor.remove_node(self.node)
            executor.shutdown(timeout_sec=0.5)
        return self.report

    def _drain(self) -> None:
        """On stop: write every message the subscriptions already hold, taken from them directly.

        A spin is not enough: ``spin_once`` serves one ready entity, which may be another than a
        subscription (the recorder's own discovery timer, a guard condition), so a spin that brings no
        message does not mean that none waits.  Under two CPU hogs a Ctrl-C after five acknowledged messages wrote two.
        """
        from ..nodes.common import take_waiting

        subs = list(self._subscriptions.values())
        handlers = {sub: sub.callback for sub in subs}
        while self.node.context.ok():
            waiting = take_waiting(subs, handlers, budget=1024)
            for data, handle in waiting:
                handle(data)
            if not waiting:
                return

    def destroy(self) -> None:
        """Destroy the node (the writer stays open: the caller closes it)."""
        for sub in self._subscriptions.values():
            self.node.destroy_subscription(sub)
        self._subscriptions.clear()
        self.node.destroy_node()


def record(bag_path: str, selector: TopicSelector, storage: str = "mcap", duration_s: float | None = None,
           context: Any = None, stop: threading.Event | SignalStop | None = None, use_sim_time: bool = False,
           max_messages: int | None = None, on_start: Callable[[Recorder], None] | None = None) -> RecordReport:
    """Record into a new bag until stopped (see :meth:`Recorder.spin`); the bag is always closed.

    The bag is opened, written and closed in the calling thread (the sqlite3
    storage must stay in the thread that opened it), so to record in the
    background run this whole function in a thread; ``on_start`` receives
    the :class:`Recorder` before spinning (e.g. to watch ``recorder.topics``).
    """
    with BagWriter(bag_path, storage=storage) as writer:
        recorder = Recorder(writer, selector, context=context, use_sim_time=use_sim_time)
        if on_start is not None:
            on_start(recorder)
        try:
            return recorder.spin(duration_s=duration_s, stop=stop, max_messages=max_messages)
        finally:
            recorder.destroy()

