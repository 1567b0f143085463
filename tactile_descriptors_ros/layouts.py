"""Descriptor layouts: the labels of a descriptor's values, sent once per layout and named by an id.

A ``Descriptor`` message carries its values and a ``layout_id``; the labels
(``<body part>/<group>/<quantity>``, up to a few thousand strings, about
three quarters of a descriptor's bytes) travel once, in a ``DescriptorLayout``
on the descriptor topic + ``_layout`` (latched).  :func:`layout_id` names a
label list; :class:`DescriptorLayouts` keeps the layouts heard and resolves
descriptors (rclpy and rosbags messages alike).

No ROS import.
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterable

__all__ = ["layout_id", "DescriptorLayouts"]


def layout_id(labels: Iterable[str]) -> str:
    """The id of a descriptor layout: the first 16 hex digits of the SHA-256 of its labels, each followed by a
    newline (UTF-8).  Equal labels in equal order, equal id."""
    h = hashlib.sha256()
    for label in labels:
        h.update(label.encode("utf-8") + b"\n")
    return h.hexdigest()[:16]


class DescriptorLayouts:
    """Descriptor labels by layout id, learned from ``DescriptorLayout`` messages (rclpy or rosbags ones).

    A ``Descriptor`` with its own labels is read as it is; one naming a
    layout not heard yet can be held (:meth:`hold`, at most ``max_held``)
    until the layout comes (:meth:`add` returns the held ones it resolves)
    or it has waited ``wait_s`` (:meth:`expire`).

    Parameters
    ----------
    max_held : int
        Most descriptors held for their layout (an older one is dropped and
        counted when another comes).
    wait_s : float
        Longest wait of a held descriptor [s].
    """

    def __init__(self, max_held: int = 1000, wait_s: float = 10.0) -> None:
        self.labels: dict[str, tuple[str, ...]] = {}
        self.max_held = int(max_held)
        self.wait_s = float(wait_s)
        self._held: list[tuple[float, object]] = []
        #: descriptors dropped because their layout never came (or too many waited)
        self.unknown = 0
        #: layouts whose id does not match their labels (refused)
        self.bad = 0

    def add(self, msg) -> list:
        """Learn a ``DescriptorLayout``; return the held descriptors it resolves, in arrival order.

        A layout whose id is not the id of its labels is refused (counted in :attr:`bad`).
        """
        labels = tuple(msg.labels)
        if layout_id(labels) != msg.layout_id:
            self.bad += 1
            return []
        self.labels[str(msg.layout_id)] = labels
        ready = [m for _, m in self._held if m.layout_id == msg.layout_id]
        self._held = [(t, m) for t, m in self._held if m.layout_id != msg.layout_id]
        return ready

    def of(self, msg) -> tuple[str, ...] | None:
        """The labels of a ``Descriptor``: its own, or its layout's; None while the layout is unknown."""
        own = getattr(msg, "labels", None)
        if own is not None and len(own):
            return tuple(own)
        return self.labels.get(str(getattr(msg, "layout_id", "")))

    def hold(self, msg, now_s: float) -> None:
        """Keep a descriptor until its layout comes (the oldest goes when :attr:`max_held` are waiting)."""
        self._held.append((now_s, msg))
        if len(self._held) > self.max_held:
            self._held.pop(0)
            self.unknown += 1

    def expire(self, now_s: float) -> list:
        """Drop (and return) the held descriptors that waited longer than ``wait_s``."""
        old = [m for t, m in self._held if now_s - t > self.wait_s]
        if old:
            self._held = [(t, m) for t, m in self._held if now_s - t <= self.wait_s]
            self.unknown += len(old)
        return old

    @property
    def held(self) -> int:
        """Descriptors waiting for their layout."""
        return len(self._held)
