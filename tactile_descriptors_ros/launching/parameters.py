"""The parameters each executable declares, from its schema: launch-time checks without starting a node.

A ROS 2 node ignores a parameter it does not declare, and rclpy refuses a
value of another type than the declared one (an integer ``3`` for a
``double`` parameter kills the node at start).  :func:`check_parameters`
catches both, and every value its schema refuses (out of range, not among
the choices), before anything starts: ``tactile launch --set``, ``--print``,
``params_file``, the robot YAML's ``nodes:`` section and the launch files
all go through :func:`~.graph.build_graph`, which calls it.  An integer
given for a ``double`` parameter becomes a float (YAML and the command line
write ``3`` for ``3.0``); every other mismatch is a
:class:`~tactile_descriptors_ros.errors.ConfigError` naming the node and
the parameter.

:data:`PARAMETER_TYPES` is built from the node schemas
(:data:`tactile_descriptors_ros.params.SCHEMAS`), the same ones the nodes
declare from.

Plain data: no rclpy import.
"""

from __future__ import annotations

import difflib
from collections.abc import Mapping
from typing import Any

from ..errors import ConfigError
from ..params import SCHEMAS
from ..params.schema import TYPES, check_value

__all__ = ["PARAMETER_TYPES", "BUILTIN_PARAMETERS", "check_parameters", "TYPES"]

#: Parameters rclpy declares on every node.
BUILTIN_PARAMETERS: dict[str, str] = {"use_sim_time": "bool", "start_type_description_service": "bool"}

#: executable -> parameter name -> type name (see :data:`TYPES`), from the node schemas.
PARAMETER_TYPES: dict[str, dict[str, str]] = {exe: schema.types() for exe, schema in SCHEMAS.items()}


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
        declare (with the closest known names), a value of another type, or
        one its schema refuses (range, choices, length, its own check).
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
        param = SCHEMAS[executable].get(name)
        out[name] = check_value(param, value, node=node) if param is not None else value
    return out
