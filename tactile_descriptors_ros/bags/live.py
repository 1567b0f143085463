"""Small rclpy helpers shared by the recorder, the player and live echo.

Only APIs present since ROS 2 Humble are used: raw subscriptions
(``create_subscription(..., raw=True)``), raw publishing
(``publisher.publish(bytes)``), ``get_topic_names_and_types`` and
``get_publishers_info_by_topic``.  Importing this module imports rclpy.
"""

from __future__ import annotations

import importlib
import re
from collections.abc import Iterable, Sequence
from typing import Any

from rosbags.interfaces import Qos

from ..errors import BagError
from .qos import adapt_offered_qos, qos_from_rclpy
from .types import full_msgtype

__all__ = [
    "DEFAULT_EXCLUDED_TOPICS",
    "message_class",
    "publisher_offers",
    "subscription_qos_for",
    "TopicSelector",
]

#: Graph bookkeeping topics that ``record --all`` and ``--regex`` leave out unless named.
DEFAULT_EXCLUDED_TOPICS = ("/rosout", "/parameter_events")


def message_class(msgtype: str) -> type:
    """The generated Python class of ``pkg/msg/Name`` (needed even to publish raw bytes).

    Raises
    ------
    BagError
        If the type's package is not installed here (source its workspace).
    """
    pkg, kind, name = full_msgtype(msgtype).split("/")
    try:
        module = importlib.import_module(f"{pkg}.{kind}")
        return getattr(module, name)
    except (ImportError, AttributeError) as exc:
        raise BagError(
            f"message type {pkg}/{kind}/{name} is not installed in this environment "
            f"(source the workspace that builds {pkg}): {exc}"
        ) from None


def publisher_offers(node: Any, topic: str) -> list[Qos]:
    """QoS profiles currently offered by the publishers of ``topic``, as rosbags profiles."""
    return [qos_from_rclpy(info.qos_profile) for info in node.get_publishers_info_by_topic(topic)]


def subscription_qos_for(offers: Sequence[Qos], depth: int) -> Any:
    """rclpy profile that matches every offer: best effort unless all publishers are reliable, etc."""
    from .qos import qos_to_rclpy

    return qos_to_rclpy(adapt_offered_qos(offers, default_depth=depth)._replace(depth=depth), default_depth=depth)


class TopicSelector:
    """Which topics to take: explicit names, a regular expression, or all (minus exclusions).

    Parameters
    ----------
    topics : iterable of str
        Exact names (always taken, even if excluded by default).
    regex : str or sequence of str, optional
        ``re.search`` pattern(s) on the topic name; a topic matching any is taken.
    all_topics : bool
    exclude : str, optional
        Pattern of topics never to take (besides :data:`DEFAULT_EXCLUDED_TOPICS`).
    """

    def __init__(self, topics: Iterable[str] = (), regex: str | Sequence[str] | None = None,
                 all_topics: bool = False, exclude: str | None = None) -> None:
        self.names = {t if t.startswith("/") else "/" + t for t in topics}
        patterns = [regex] if isinstance(regex, str) else [r for r in (regex or ()) if r]
        try:
            self.regexes = [re.compile(r) for r in patterns if r]
            self.exclude = re.compile(exclude) if exclude else None
        except re.error as exc:
            raise BagError(f"bad topic pattern: {exc}") from None
        self.all_topics = all_topics
        if not (self.names or self.regexes or self.all_topics):
            raise BagError("no topics selected: name topics, give --regex PATTERN, or --all")

    def __call__(self, topic: str) -> bool:
        if topic in self.names:
            return True
        if topic in DEFAULT_EXCLUDED_TOPICS or (self.exclude and self.exclude.search(topic)):
            return False
        if self.all_topics:
            return True
        return any(r.search(topic) for r in self.regexes)
