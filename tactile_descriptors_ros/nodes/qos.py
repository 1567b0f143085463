"""QoS of every topic as node parameters.

Sensor-data QoS mismatches are the most common complaint in tactile driver
issue trackers: a ``RELIABLE`` subscription never matches a ``BEST_EFFORT``
publisher, and the symptom is silence.  Every publisher and subscription of
the package's nodes therefore reads its QoS from three parameters named
after the endpoint::

    qos.<endpoint>.reliability   reliable | best_effort | system_default
    qos.<endpoint>.durability    volatile | transient_local | system_default
    qos.<endpoint>.depth         history depth (KEEP_LAST), 1 .. 1,000,000
    qos.<endpoint>.history       keep_last | keep_all (only where an endpoint offers the choice)

The defaults are chosen so that the package's own graph always matches and a
foreign publisher or subscriber most likely does:

* drivers *publish* frames ``reliable`` (a reliable offer matches both
  reliable and best-effort requests, including ``ros2 topic echo``'s);
* the window node *subscribes* to frames ``best_effort`` (a best-effort request
  matches both reliable and best-effort publishers, e.g. a driver configured
  with ``SensorDataQoS`` or a bag replayed with its recorded offers);
* descriptors, predictions and labels are rare and each one matters (a lost
  label is a lost update): reliable on both sides, depth 10 to 50.
"""

from __future__ import annotations

from ..errors import ConfigError

__all__ = ["RELIABILITIES", "DURABILITIES", "HISTORIES", "qos_of", "qos_profile"]

from ..params.common import DURABILITIES, HISTORIES, MAX_QOS_DEPTH, RELIABILITIES


def qos_profile(reliability: str, durability: str, depth: int, endpoint: str = "?", history: str = "keep_last"):
    """Build an :class:`rclpy.qos.QoSProfile` from policy names.

    Raises
    ------
    ConfigError
        Naming the offending ``qos.<endpoint>.*`` parameter.
    """
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

    rel = str(reliability).lower()
    dur = str(durability).lower()
    if rel not in RELIABILITIES:
        raise ConfigError(f"must be one of {RELIABILITIES}, got {reliability!r}", key=f"qos.{endpoint}.reliability")
    if dur not in DURABILITIES:
        raise ConfigError(f"must be one of {DURABILITIES}, got {durability!r}", key=f"qos.{endpoint}.durability")
    if isinstance(depth, bool) or not isinstance(depth, int) or not 1 <= depth <= MAX_QOS_DEPTH:
        raise ConfigError(f"must be an integer from 1 to {MAX_QOS_DEPTH}, got {depth!r}", key=f"qos.{endpoint}.depth")
    if history not in HISTORIES:
        raise ConfigError(f"must be one of {HISTORIES}, got {history!r}", key=f"qos.{endpoint}.history")
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST if history == "keep_last" else HistoryPolicy.KEEP_ALL,
        depth=int(depth),
        reliability={"reliable": ReliabilityPolicy.RELIABLE, "best_effort": ReliabilityPolicy.BEST_EFFORT,
                     "system_default": ReliabilityPolicy.SYSTEM_DEFAULT}[rel],
        durability={"volatile": DurabilityPolicy.VOLATILE, "transient_local": DurabilityPolicy.TRANSIENT_LOCAL,
                    "system_default": DurabilityPolicy.SYSTEM_DEFAULT}[dur],
    )


def qos_of(params, endpoint: str):
    """The :class:`rclpy.qos.QoSProfile` of ``endpoint`` from a node's declared ``qos.<endpoint>.*`` parameters
    (:mod:`tactile_descriptors_ros.params.common`, read-only: an endpoint's QoS is fixed when it is made)."""
    prefix = f"qos.{endpoint}"
    history = params.get(f"{prefix}.history", "keep_last")
    return qos_profile(params[f"{prefix}.reliability"], params[f"{prefix}.durability"], params[f"{prefix}.depth"],
                       endpoint, history)
