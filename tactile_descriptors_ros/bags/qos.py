"""QoS profiles as rosbag2 stores them (``offered_qos_profiles``), and their rclpy equivalents.

A bag remembers, per topic, the QoS the publishers offered while it was
recorded.  Replaying with a different reliability or durability is the most
common reason a replayed tactile stream reaches nobody (a ``RELIABLE``
subscriber never matches a ``BEST_EFFORT`` publisher; a late-joining
``TRANSIENT_LOCAL`` subscriber misses a ``VOLATILE`` latched label), so the
recorder stores the offers and the player adapts to them the way rosbag2 does:

* reliability: ``RELIABLE`` only if every offer was reliable, else ``BEST_EFFORT``;
* durability: ``TRANSIENT_LOCAL`` only if every offer was, else ``VOLATILE``;
* history: ``KEEP_LAST`` with the largest known depth (discovery does not
  carry depths, so recorded offers usually have none: then ``default_depth``).

Infinite deadlines, lifespans and lease durations are written as ``0, 0``
(the middleware default, which is infinite): Humble wrote them as
``2147483647, 4294967295`` and Jazzy as ``9223372036, 854775807``; both are
read back as infinite.  rclpy is imported only by the rclpy conversions.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime

__all__ = [
    "DEFAULT_DEPTH",
    "make_qos",
    "SENSOR_DATA_QOS",
    "RELIABLE_QOS",
    "LATCHED_QOS",
    "adapt_offered_qos",
    "qos_to_dict",
    "qos_from_rclpy",
    "qos_to_rclpy",
    "is_infinite",
]

#: Depth used when a recorded offer does not say (rosbag2's default too).
DEFAULT_DEPTH = 10

_ZERO = QosTime(0, 0)
_INFINITE_NS = (1 << 63) - 1
_LEGACY_INFINITE = {(2147483647, 4294967295), (9223372036, 854775807)}


def make_qos(
    reliability: str = "reliable",
    durability: str = "volatile",
    depth: int = DEFAULT_DEPTH,
    history: str = "keep_last",
) -> Qos:
    """A rosbags :class:`~rosbags.interfaces.Qos` from policy names.

    Parameters
    ----------
    reliability : {"reliable", "best_effort", "system_default"}
    durability : {"volatile", "transient_local", "system_default"}
    depth : int
        History depth (``KEEP_LAST``).
    history : {"keep_last", "keep_all", "system_default"}
    """
    try:
        return Qos(
            QosHistory[history.upper()],
            int(depth),
            QosReliability[reliability.upper()],
            QosDurability[durability.upper()],
            _ZERO,
            _ZERO,
            QosLiveliness.SYSTEM_DEFAULT,
            _ZERO,
            False,
        )
    except KeyError as exc:
        raise ValueError(f"unknown QoS policy name {exc.args[0]!r}") from None


#: ``rclpy.qos.qos_profile_sensor_data``: best effort, volatile, depth 5.
SENSOR_DATA_QOS = make_qos("best_effort", "volatile", 5)
#: The rclpy default for publishers: reliable, volatile, depth 10.
RELIABLE_QOS = make_qos("reliable", "volatile", DEFAULT_DEPTH)
#: Latched: reliable, transient local, depth 1.
LATCHED_QOS = make_qos("reliable", "transient_local", 1)


def is_infinite(t: QosTime) -> bool:
    """Whether a stored duration means "infinite" (0, or a legacy infinite encoding)."""
    return (t.sec, t.nsec) in _LEGACY_INFINITE or t.sec * 1_000_000_000 + t.nsec >= _INFINITE_NS


def adapt_offered_qos(offers: Sequence[Qos], default_depth: int = DEFAULT_DEPTH) -> Qos:
    """One profile compatible with every recorded offer (see the module docstring).

    Parameters
    ----------
    offers : sequence of Qos
        The topic's ``offered_qos_profiles``; may be empty.
    default_depth : int
        Depth when no offer carries one.

    Returns
    -------
    Qos
        With only history, depth, reliability and durability set; deadline,
        lifespan and liveliness are left at the middleware default.
    """
    if not offers:
        return make_qos("reliable", "volatile", default_depth)
    reliable = all(q.reliability == QosReliability.RELIABLE for q in offers)
    latched = all(q.durability == QosDurability.TRANSIENT_LOCAL for q in offers)
    depths = [q.depth for q in offers if q.history == QosHistory.KEEP_LAST and q.depth > 0]
    keep_all = any(q.history == QosHistory.KEEP_ALL for q in offers)
    return make_qos(
        "reliable" if reliable else "best_effort",
        "transient_local" if latched else "volatile",
        max(depths) if depths else default_depth,
        "keep_all" if keep_all else "keep_last",
    )


def qos_to_dict(qos: Qos) -> dict[str, Any]:
    """Readable form: policy names in lower case, durations in ns (``None`` = infinite)."""

    def ns(t: QosTime) -> int | None:
        return None if is_infinite(t) or (t.sec == 0 and t.nsec == 0) else t.sec * 1_000_000_000 + t.nsec

    return {
        "history": qos.history.name.lower(),
        "depth": qos.depth,
        "reliability": qos.reliability.name.lower(),
        "durability": qos.durability.name.lower(),
        "deadline_ns": ns(qos.deadline),
        "lifespan_ns": ns(qos.lifespan),
        "liveliness": qos.liveliness.name.lower(),
        "liveliness_lease_duration_ns": ns(qos.liveliness_lease_duration),
    }


def _time_from_ns(nanoseconds: int) -> QosTime:
    if nanoseconds <= 0 or nanoseconds >= _INFINITE_NS:
        return _ZERO
    return QosTime(nanoseconds // 1_000_000_000, nanoseconds % 1_000_000_000)


def _enum_by_value(enum: Any, value: int, fallback: Any) -> Any:
    try:
        return enum(int(value))
    except ValueError:
        return fallback


def qos_from_rclpy(profile: Any) -> Qos:
    """Convert an ``rclpy.qos.QoSProfile`` (e.g. from ``get_publishers_info_by_topic``)."""
    return Qos(
        _enum_by_value(QosHistory, profile.history, QosHistory.UNKNOWN),
        int(profile.depth),
        _enum_by_value(QosReliability, profile.reliability, QosReliability.UNKNOWN),
        _enum_by_value(QosDurability, profile.durability, QosDurability.UNKNOWN),
        _time_from_ns(profile.deadline.nanoseconds),
        _time_from_ns(profile.lifespan.nanoseconds),
        _enum_by_value(QosLiveliness, profile.liveliness, QosLiveliness.UNKNOWN),
        _time_from_ns(profile.liveliness_lease_duration.nanoseconds),
        bool(profile.avoid_ros_namespace_conventions),
    )


def qos_to_rclpy(qos: Qos, default_depth: int = DEFAULT_DEPTH) -> Any:
    """An ``rclpy.qos.QoSProfile`` with the history, depth, reliability and durability of ``qos``.

    Policies the middleware cannot be asked for (``UNKNOWN``) become the
    rclpy defaults (keep last, reliable, volatile).
    """
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    history = HistoryPolicy.KEEP_ALL if qos.history == QosHistory.KEEP_ALL else HistoryPolicy.KEEP_LAST
    reliability = {
        QosReliability.BEST_EFFORT: ReliabilityPolicy.BEST_EFFORT,
        QosReliability.SYSTEM_DEFAULT: ReliabilityPolicy.SYSTEM_DEFAULT,
    }.get(qos.reliability, ReliabilityPolicy.RELIABLE)
    durability = {
        QosDurability.TRANSIENT_LOCAL: DurabilityPolicy.TRANSIENT_LOCAL,
        QosDurability.SYSTEM_DEFAULT: DurabilityPolicy.SYSTEM_DEFAULT,
    }.get(qos.durability, DurabilityPolicy.VOLATILE)
    depth = qos.depth if qos.depth > 0 else default_depth
    return QoSProfile(history=history, depth=depth, reliability=reliability, durability=durability)
