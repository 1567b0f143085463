"""Message sources for ``tactile echo``: a bag, or a live topic through a raw subscription.

Both yield ``(BagMessage, decoded)`` pairs, decoded by the rosbags type
store, so :class:`~tactile_descriptors_ros.bags.summary.EchoTracker` sees
the same objects whether the bytes came from a file or the network.
"""

from __future__ import annotations

import queue
import time
from collections.abc import Iterator
from typing import Any

from ..errors import BagError
from ..topics import layout_topic
from .io import BagMessage, BagReader
from .types import ensure_types, tactile_typestore

_DESCRIPTOR = "tactile_descriptors_msgs/msg/Descriptor"
_LAYOUT = "tactile_descriptors_msgs/msg/DescriptorLayout"

__all__ = ["echo_bag", "echo_live", "type_constants"]


def type_constants(store: Any) -> dict[str, list]:
    """Message type -> constants ``(name, type, value)`` known to ``store``."""
    return {name: list(spec[0]) for name, spec in store.fielddefs.items()}


def echo_bag(bag_path: str, topic: str, count: int | None = None) -> Iterator[tuple[BagMessage, Any]]:
    """Decoded messages of one topic of a bag, in log-time order.

    For a descriptor topic the bag's layouts (the topic + ``_layout``) come
    along, so a summary can name the values; ``count`` counts only ``topic``.
    """
    with BagReader(bag_path) as reader:
        topics = [topic]
        if layout_topic(topic) in reader.info.topics:
            topics.append(layout_topic(topic))
        n = 0
        for msg in reader.messages(topics):
            if msg.topic == topic:
                if count is not None and n >= count:
                    return
                n += 1
            yield msg, reader.deserialize(msg)


def echo_live(topic: str, count: int | None = None, timeout_s: float | None = None,
              discovery_timeout_s: float = 5.0, msgtype: str | None = None, context: Any = None,
              depth: int = 100) -> Iterator[tuple[BagMessage, Any]]:
    """Decoded messages arriving on a live topic (a descriptor topic's layouts come along, latched).

    Parameters
    ----------
    topic : str
    count : int, optional
        Stop after this many messages.
    timeout_s : float, optional
        Stop after this long (wall time) in total.
    discovery_timeout_s : float
        How long to wait for a publisher when ``msgtype`` is not given.
    msgtype : str, optional
        Type to subscribe with; discovered from the graph when omitted.
    context : rclpy.Context, optional
    depth : int
        Subscription depth.

    Raises
    ------
    BagError
        If no publisher appears within ``discovery_timeout_s`` (and no type was given).
    """
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node

    from .live import message_class, publisher_offers, subscription_qos_for

    topic = topic if topic.startswith("/") else "/" + topic
    node = Node("tactile_echo", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    store = tactile_typestore()
    try:
        deadline = time.monotonic() + discovery_timeout_s
        offers = []
        while True:
            types = dict(node.get_topic_names_and_types()).get(topic, [])
            offers = publisher_offers(node, topic)
            if offers and (types or msgtype):
                break
            if time.monotonic() >= deadline:
                if msgtype:
                    break
                raise BagError(f"no publisher on {topic} after {discovery_timeout_s:g} s (is the graph running, "
                               "same ROS_DOMAIN_ID and ROS_AUTOMATIC_DISCOVERY_RANGE?)")
            executor.spin_once(timeout_sec=0.05)
        if msgtype is None:
            if len(types) != 1:
                raise BagError(f"{topic} is published with several types {types}; pass the type")
            msgtype = types[0]
        ensure_types(store, [msgtype])
        inbox: queue.SimpleQueue[tuple[str, str, int, bytes]] = queue.SimpleQueue()
        clock = node.get_clock()
        node.create_subscription(message_class(msgtype), topic,
                                 lambda data: inbox.put((topic, msgtype, clock.now().nanoseconds, data)),
                                 subscription_qos_for(offers, depth), raw=True)
        if msgtype == _DESCRIPTOR:  # the layouts name the values: latched beside the descriptors
            from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

            ensure_types(store, [_LAYOUT])
            companion = layout_topic(topic)
            node.create_subscription(message_class(_LAYOUT), companion,
                                     lambda data: inbox.put((companion, _LAYOUT, clock.now().nanoseconds, data)),
                                     QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                                                durability=DurabilityPolicy.TRANSIENT_LOCAL), raw=True)
        end = time.monotonic() + timeout_s if timeout_s is not None else None
        n = 0
        while node.context.ok():
            if count is not None and n >= count:
                return
            if end is not None and time.monotonic() >= end:
                return
            executor.spin_once(timeout_sec=0.05)
            while not inbox.empty():
                name, kind, t_ns, data = inbox.get()
                msg = BagMessage(name, kind, t_ns, bytes(data))
                yield msg, store.deserialize_cdr(msg.data, kind)
                if name == topic:
                    n += 1
                    if count is not None and n >= count:
                        return
    finally:
        executor.remove_node(node)
        executor.shutdown(timeout_sec=0.5)
        node.destroy_node()
