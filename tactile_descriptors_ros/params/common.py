"""Parameters several nodes share: robot, frame ids, topics, diagnostics, and the QoS of an endpoint."""

from __future__ import annotations

from ..errors import ConfigError
from .schema import Param

__all__ = [
    "frames_serialized",
    "RELIABILITIES",
    "DURABILITIES",
    "HISTORIES",
    "MAX_QOS_DEPTH",
    "qos",
    "robot",
    "body_parts",
    "frame_id",
    "topic_pattern",
    "diagnostics_period",
    "check_frame_id",
    "check_topic_pattern",
    "check_not_empty",
]

RELIABILITIES = ("reliable", "best_effort", "system_default")
DURABILITIES = ("volatile", "transient_local", "system_default")
HISTORIES = ("keep_last", "keep_all")
#: Deepest KEEP_LAST history accepted (a deeper one preallocates that many samples: a typo, not a setting).
MAX_QOS_DEPTH = 1_000_000


def check_frame_id(value: str) -> None:
    """A TF frame id: not empty, no blanks."""
    if not value:
        raise ConfigError("must not be empty: every message names its frame")
    if any(c.isspace() for c in value):
        raise ConfigError(f"must not hold blanks, got {value!r}")


def check_topic_pattern(value: str) -> None:
    """A topic name pattern whose only field is ``{body_part}``."""
    if not value:
        raise ConfigError("must not be empty")
    try:
        value.format(body_part="x")
    except (KeyError, IndexError, ValueError) as exc:
        raise ConfigError(f"may hold only the field {{body_part}}, got {value!r} ({exc!r})") from None


def check_not_empty(value: list) -> None:
    """A list with at least one item, none of them empty."""
    if not value or any(v == "" for v in value):
        raise ConfigError(f"needs at least one item and no empty one, got {value!r}")


def qos(endpoint: str, reliability: str, durability: str, depth: int, history: str | None = None) -> tuple[Param, ...]:
    """``qos.<endpoint>.{reliability,durability,depth}``, read-only (a QoS is fixed when the endpoint is made).

    With ``history`` (``keep_last`` or ``keep_all``), also ``qos.<endpoint>.history``: the endpoint offers the
    choice; without, its history is KEEP_LAST.
    """
    params = (
        Param(f"qos.{endpoint}.reliability", "string", f"QoS reliability of '{endpoint}'", default=reliability,
              choices=RELIABILITIES, normalize=str.lower),
        Param(f"qos.{endpoint}.durability", "string", f"QoS durability of '{endpoint}'", default=durability,
              choices=DURABILITIES, normalize=str.lower),
        Param(f"qos.{endpoint}.depth", "integer", f"QoS history depth of '{endpoint}' (KEEP_LAST)", default=depth,
              range=(1, MAX_QOS_DEPTH), unit="messages"),
    )
    if history is None:
        return params
    return (*params, Param(f"qos.{endpoint}.history", "string", f"QoS history of '{endpoint}' (keep_all: no sample "
                           "replaced, losses counted)", default=history, choices=HISTORIES, normalize=str.lower))


def robot(description: str = "robot description: a shipped name (shadow_hand, nao) or a YAML path") -> Param:
    """``robot``: the robot description (required by the nodes that read body parts)."""
    return Param("robot", "string", description, default="")


def body_parts(derived: str) -> Param:
    """``body_parts``: the body parts a node serves (default computed by the node from the robot)."""
    return Param("body_parts", "string_array", "body parts this node serves, in the robot description's names",
                 derived=derived, check=check_not_empty, max_items=100_000)


def frame_id(description: str, derived: str | None = None, default: str | None = None) -> Param:
    """``frame_id``: ``header.frame_id`` of what the node publishes; tunable."""
    return Param("frame_id", "string", description, default=default, derived=derived, tunable=True,
                 check=check_frame_id, max_chars=256)


def topic_pattern(default: str) -> Param:
    """``frames_topic``: the frames topic of a body part, ``{body_part}`` filled in."""
    return Param("frames_topic", "string", "frames topic of a body part ({body_part} is its name)", default=default,
                 check=check_topic_pattern, max_chars=256)


def diagnostics_period() -> Param:
    """``diagnostics_period_s``: period of ``/diagnostics`` (wall time)."""
    return Param("diagnostics_period_s", "double", "period of the node's /diagnostics (wall time)", default=1.0,
                 unit="s", range=(0.01, 3600.0))


def frames_serialized(what: str = "take SkinPartFrames serialised and read them") -> Param:
    """``frames.serialized``: skin cells' frames handled as their CDR bytes, in one compiled pass (``what``)."""
    return Param("frames.serialized", "bool", f"{what} in one compiled pass (false: rclpy builds each message; "
                 "lab/docs/performance.md#latency)", default=True)
