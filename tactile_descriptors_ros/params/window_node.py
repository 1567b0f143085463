"""Parameters of ``window_node``: frames -> contact gate -> windows -> descriptors."""

from __future__ import annotations

from ..core.robot import CHANNEL_MODES, LAYOUT_MODES, WINDOW_MODES
from ..core.windowing import CUT_AHEAD_S
from ..topics import FRAMES_TOPIC
from .common import (
    body_parts,
    check_not_empty,
    diagnostics_period,
    frame_id,
    frames_serialized,
    qos,
    robot,
    topic_pattern,
)
from .schema import NodeSchema, Param, join

__all__ = ["WINDOW_NODE"]

#: longest window, exploration, block or wait the node accepts [s]: an hour of a touch is not a touch
_LONGEST_S = 3600.0
#: a force no tactile sensor here measures [N]
_MAX_FORCE_N = 1000.0


def _windower(name: str, description: str, *, low: float, high: float = _LONGEST_S, unit: str = "s",
              **source) -> Param:
    """A setting of the core Windower: tunable, checked with the others by the windower (hook ``windower``)."""
    return Param(name, "double", description, unit=unit, range=(low, high), tunable=True, apply="windower",
                 **source)


WINDOW_NODE = NodeSchema("window_node", join(
    robot(),
    body_parts("all body parts of the robot"),
    Param("window.mode", "string", "window mode: exploration (contact onset to release) or fixed (length, hop)",
          robot="window.mode", choices=WINDOW_MODES),
    Param("descriptor.layout", "string", "descriptor layout: concat (body parts in the robot's order, eq. 12) or "
          "pooled (mean over the body parts in contact)", robot="descriptor.layout", choices=LAYOUT_MODES),
    Param("descriptor.channels", "string", "legacy spelling of the feature groups: averaged = [paper], "
          "per_channel = [per_channel]; '' = descriptor.groups decides (set one of the two)",
          robot="descriptor.channels", choices=("", *CHANNEL_MODES)),
    Param("descriptor.groups", "string_array", "feature groups in descriptor order: paper, per_channel, bands, "
          "levels (or levels:<ch>,<ch>), statistics; checked against every served cell type",
          robot="descriptor.groups", check=check_not_empty, max_items=64, max_chars=256),
    Param("descriptor.block_s", "double", "block averaging: describe a window by the mean over its blocks of this "
          "long (Activity in log); 0 = one descriptor of the whole window", robot="descriptor.block_s", unit="s",
          range=(0.0, _LONGEST_S)),
    Param("descriptor.block_hop_s", "double", "largest step between blocks, at most descriptor.block_s",
          robot="descriptor.block_hop_s", unit="s", range=(0.001, _LONGEST_S)),
    _windower("window.length_s", "fixed window length", low=0.001, robot="window.length_s"),
    _windower("window.hop_s", "fixed window hop", low=0.001, robot="window.hop_s"),
    _windower("window.min_duration_s", "shortest exploration kept", low=0.0, robot="window.min_duration_s"),
    _windower("window.max_duration_s", "longest exploration window", low=0.001, robot="window.max_duration_s"),
    _windower("window.release_s", "force below the release threshold this long ends an exploration", low=0.0,
              high=60.0, robot="window.release_s"),
    Param("window.describe_ahead", "bool", "describe an exploration's window while its release time runs, so its "
          "descriptor leaves when the release is decided (the same bits; false: described after the decision)",
          default=True),
    Param("window.cut_ahead", "bool", f"copy a fixed window's samples once its end is within {CUT_AHEAD_S * 1e3:g} "
          "ms of the newest ones, so that closing it copies only the last ones (the same window; false: all copied "
          "when it closes)", default=True),
    _windower("window.lateness_s", "wait for late cells after a fixed window's end", low=0.0, high=60.0,
              default=0.05),
    _windower("contact.force_threshold_n", "contact gate F_t (eq. 13, 27): a cell is in contact at or above it; "
              "an exploration starts there", low=0.0, high=_MAX_FORCE_N, unit="N", robot="contact.force_threshold_n"),
    _windower("contact.release_threshold_n", "an exploration ends below this force (at most F_t: hysteresis)",
              low=0.0, high=_MAX_FORCE_N, unit="N", robot="contact.release_threshold_n"),
    frame_id("header.frame_id of the descriptors, which describe the whole robot",
             derived="the robot's root frame (geometry.root_frame; the robot's name without a geometry section)"),
    Param("exploration_id_stride", "integer", "published exploration id = local id * stride + offset (set by the "
          "scale-out graph: the number of window nodes)", default=1, range=(1, 1_000_000)),
    Param("exploration_id_offset", "integer", "see exploration_id_stride (this node's index, below the stride)",
          default=0, range=(0, 999_999)),
    topic_pattern(FRAMES_TOPIC),
    frames_serialized(),
    Param("frames.drain_max", "integer", "frames messages taken from the queues per callback besides its own, "
          "handed to the windower at once (0 = one per callback; lab/docs/performance.md#latency)", default=1000,
          range=(0, 1_000_000), unit="messages", tunable=True),
    diagnostics_period(),
    Param("diagnostics.silent_after_s", "double", "a served body part that sent no frames for this long is reported "
          "silent (WARN)", default=2.0, unit="s", range=(0.1, 3600.0), tunable=True),
    qos("frames", "best_effort", "volatile", 256),
    qos("descriptor", "reliable", "volatile", 10),
    qos("layout", "reliable", "transient_local", 1),
))
