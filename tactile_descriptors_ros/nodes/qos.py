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

from dataclasses import dataclass

from ..errors import ConfigError

__all__ = ["QosDefaults", "RELIABILITIES", "DURABILITIES", "HISTORIES", "MAX_DEPTH", "declare_qos", "qos_profile"]

RELIABILITIES = ("reliable", "best_effort", "system_default")
DURABILITIES = ("volatile", "transient_local", "system_default")
HISTORIES = ("keep_last", "keep_all")
#: Deepest history accepted (a deeper one is a typo, and preallocates that many samples).
MAX_DEPTH = 1_000_000


@dataclass(frozen=True)
class QosDefaults:
    """Default QoS of one endpoint (overridable by parameters)."""

    reliability: str = "reliable"
    durability: str = "volatile"
    depth: int = 10
    #: ``keep_last`` or ``keep_all``; None: KEEP_LAST, and no ``history`` parameter
    history: str | None = None


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
    if isinstance(depth, bool) or not isinstance(depth, int) or not 1 <= depth <= MAX_DEPTH:
        raise ConfigError(f"must be an integer from 1 to {MAX_DEPTH}, got {depth!r}", key=f"qos.{endpoint}.depth")
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


def declare_qos(node, endpoint: str, defaults: QosDefaults):
    """Declare ``qos.<endpoint>.{reliability,durability,depth}`` on ``node`` and return the profile.

    Read-only: an endpoint's QoS is fixed when it is created.  The choices
    and the depth's range are in the descriptors (``ros2 param describe``).
    """
    from .common import declare

    prefix = f"qos.{endpoint}"
    rel = declare(node, f"{prefix}.reliability", defaults.reliability, f"QoS reliability of '{endpoint}'",
                  choices=RELIABILITIES, resolve=str.lower)
    dur = declare(node, f"{prefix}.durability", defaults.durability, f"QoS durability of '{endpoint}'",
                  choices=DURABILITIES, resolve=str.lower)
    depth = declare(node, f"{prefix}.depth", defaults.depth, f"QoS history depth of '{endpoint}' (KEEP_LAST)",
                    minimum=1, maximum=MAX_DEPTH)
    history = "keep_last"
    if defaults.history is not None:
        history = declare(node, f"{prefix}.history", defaults.history,
                          f"QoS history of '{endpoint}' (keep_all: no sample replaced, losses counted)",
                          choices=HISTORIES, resolve=str.lower)
    return qos_profile(rel, dur, depth, endpoint, history)
