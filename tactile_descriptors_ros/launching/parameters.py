"""The parameters each executable declares, by type: launch-time checks without starting a node.

A ROS 2 node ignores a parameter it does not declare, and rclpy refuses a
value of another type than the declared one (an integer ``3`` for a
``double`` parameter kills the node at start).  :func:`check_parameters`
catches both before anything starts: ``tactile launch --set``, ``--print``,
the robot YAML's ``nodes:`` section and the launch files all go through
:func:`~.graph.build_graph`, which calls it.  An integer given for a
``double`` parameter becomes a float (YAML and the command line write
``3`` for ``3.0``); every other mismatch is a
:class:`~tactile_descriptors_ros.errors.ConfigError` naming the node and the
parameter.

:data:`PARAMETER_TYPES` is checked against what the nodes really declare by
``test/launching/test_parameters.py`` (it starts each node in-process), so a
parameter added to a node without an entry here fails a test.

Plain data: no rclpy import.
"""

from __future__ import annotations

import difflib
from collections.abc import Mapping
from typing import Any

from ..errors import ConfigError

__all__ = ["PARAMETER_TYPES", "BUILTIN_PARAMETERS", "check_parameters", "TYPES"]

#: Type names (as ``ros2 param describe`` prints them, lower case).
TYPES = ("bool", "integer", "double", "string", "string_array", "integer_array", "double_array", "bool_array")

#: Parameters rclpy declares on every node.
BUILTIN_PARAMETERS: dict[str, str] = {"use_sim_time": "bool", "start_type_description_service": "bool"}

_QOS = ("reliability", "durability", "depth")


def _qos(*endpoints: str) -> dict[str, str]:
    return {f"qos.{e}.{k}": ("integer" if k == "depth" else "string") for e in endpoints for k in _QOS}


_DRIVER = {
    "robot": "string", "body_parts": "string_array", "transport": "string", "stamp_source": "string",
    "resync_s": "double", "tare_on_start_s": "double", "tare.window_s": "double", "contact_threshold_n": "double",
    "frames_topic": "string", "serial.port": "string", "serial.baudrate": "integer", "sim.scene": "string",
    "sim.speed": "double", "autostart": "bool", "diagnostics_period_s": "double", "reconnect_s": "double",
    "read_period_s": "double",
    **_qos("frames"),
}

#: executable -> parameter name -> type name (see :data:`TYPES`).
PARAMETER_TYPES: dict[str, dict[str, str]] = {
    "biotac_driver": {
        **_DRIVER, "frame_pattern": "string", "word_rate_hz": "double", "batch_frames": "integer",
        "wire": "string", "tare.track_s": "double", "tare.track_band_n": "double", "pdc_pa_per_count": "double",
        "cheetah.port": "integer", "cheetah.bitrate_khz": "integer",
    },
    "skin_driver": {
        **_DRIVER, "batch_s": "double", "can.interface": "string", "can.channel": "string",
        "can.bitrate": "integer", "sim.wire": "string", "sim.loop": "bool",
    },
    "window_node": {
        "robot": "string", "body_parts": "string_array", "window.mode": "string", "descriptor.layout": "string",
        "descriptor.channels": "string", "descriptor.groups": "string_array", "descriptor.block_s": "double",
        "descriptor.block_hop_s": "double", "window.length_s": "double",
        "window.hop_s": "double",
        "window.min_duration_s": "double", "window.max_duration_s": "double", "window.release_s": "double",
        "window.lateness_s": "double", "contact.force_threshold_n": "double",
        "contact.release_threshold_n": "double", "frame_id": "string", "exploration_id_stride": "integer",
        "exploration_id_offset": "integer", "frames_topic": "string", "frames.drain_max": "integer",
        "diagnostics_period_s": "double", **_qos("frames", "descriptor"),
    },
    "classifier_node": {
        "robot": "string", "model_path": "string", "eta": "double", "log_activity": "bool",
        "standardize": "bool", "pa_update": "string", "pa_average": "bool", "label_horizon": "integer",
        "save_after_update": "bool", "load_model": "bool", "frame_id": "string", "diagnostics_period_s": "double",
        "label_expiry_explorations": "integer", "max_class_name_chars": "integer", "label_wait_s": "double",
        "max_classes": "integer", "max_exploration_id_step": "integer", "label_hold_s": "double",
        "prediction_order": "string", "clock_jump_s": "double", "enable_reset": "bool",
        "qos.label.history": "string", **_qos("descriptor", "label", "prediction"),
    },
    "contact_node": {
        "robot": "string", "body_parts": "string_array", "contact.force_threshold_n": "double",
        "contact.floor_n": "double", "view.rate_hz": "double", "view.force_max_n": "double",
        "view.stale_s": "double", "view.image_size_px": "integer", "view.refresh_s": "double",
        "view.markers": "bool", "view.images": "bool", "frames_topic": "string", "frames.drain_max": "integer",
        "diagnostics_period_s": "double",
        **_qos("frames", "contact", "view", "prediction"),
    },
    "tf_publisher": {
        "robot": "string", "publish_links": "bool", "publish_sites": "bool", "diagnostics_period_s": "double",
    },
}


def _is(value: Any, kind: str) -> bool:
    if kind == "bool":
        return isinstance(value, bool)
    if kind == "integer":
        return isinstance(value, int) and not isinstance(value, bool)
    if kind == "double":
        return isinstance(value, float)
    if kind == "string":
        return isinstance(value, str)
    if kind.endswith("_array"):
        return isinstance(value, (list, tuple)) and all(_is(v, kind[:-6]) for v in value)
    raise ValueError(f"unknown parameter type {kind!r}")


def _coerce(value: Any, kind: str) -> Any:
    """``value`` as ``kind``: integers widen to doubles (also inside arrays); else unchanged."""
    if kind == "double" and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if kind == "double_array" and isinstance(value, (list, tuple)):
        return [_coerce(v, "double") for v in value]
    return value


def check_parameters(node: str, executable: str, parameters: Mapping[str, Any]) -> dict[str, Any]:
    """Check ``parameters`` of one node against what its executable declares; return them coerced.

    Parameters
    ----------
    node : str
        Node name (for the error message).
    executable : str
        One of :data:`PARAMETER_TYPES`.
    parameters : mapping
        Flat parameter names to values.

    Raises
    ------
    ConfigError
        Keyed ``<node>.<parameter>``: a parameter the executable does not
        declare (with the closest known names), or a value of another type.
    """
    known = {**BUILTIN_PARAMETERS, **PARAMETER_TYPES[executable]}
    out: dict[str, Any] = {}
    for name, value in parameters.items():
        kind = known.get(name)
        if kind is None:
            near = difflib.get_close_matches(name, list(known), n=3)
            hint = f"; did you mean {', '.join(near)}?" if near else ""
            raise ConfigError(f"{executable} has no parameter {name!r}{hint} (its parameters: "
                              f"{', '.join(sorted(PARAMETER_TYPES[executable]))})", key=f"{node}.{name}")
        value = _coerce(value, kind)
        if not _is(value, kind):
            raise ConfigError(f"expects a {kind.replace('_', ' ')}, got {value!r} ({type(value).__name__})",
                              key=f"{node}.{name}")
        out[name] = value
    return out
