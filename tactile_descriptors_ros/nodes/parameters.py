"""A node's parameters, declared from its schema and kept current by ``ros2 param set``.

:class:`NodeParameters` declares each :class:`~tactile_descriptors_ros.params.schema.Param`
of a node's :class:`~tactile_descriptors_ros.params.schema.NodeSchema` with
its ``ParameterDescriptor`` (description with unit, ``FloatingPointRange`` /
``IntegerRange``, choices in ``additional_constraints``, ``read_only``), and
holds the values: ``params["window.length_s"]`` is always the value in force.

A set (``ros2 param set``, ``set_parameters``, an atomic request) is checked
completely before anything is applied: every parameter's type, finiteness,
range, choices, length and own check (:func:`~tactile_descriptors_ros.params.schema.check_value`),
then each apply hook the request touches, with the node's other current
values (a window length with its hop), so a request is applied whole or
refused whole, with the reason.  A refusal, and any error in a check or an
apply, is an answer: it never stops the node.

Tunable parameters without an apply hook need nothing more: the node reads
``params[name]`` where it uses the value.
"""

from __future__ import annotations

import traceback
from collections.abc import Callable, Iterator, Mapping
from typing import Any

from ..errors import ConfigError
from ..params.schema import NodeSchema, Param, check_value, describe_range, robot_value

__all__ = ["NodeParameters", "parameter_descriptor", "ApplyHook"]

#: ``hook(values, changed)``: ``values`` all of the node's current values with the request's changes, ``changed``
#: the names the request sets; raises ConfigError to refuse, returns a function that applies them (or None).
ApplyHook = Callable[[Mapping[str, Any], frozenset], Callable[[], None] | None]


def parameter_descriptor(param: Param):
    """The ``rcl_interfaces/ParameterDescriptor`` of ``param`` (what ``ros2 param describe`` shows)."""
    from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor

    text = param.description
    if param.unit:
        text += f" [{param.unit}]"
    desc = ParameterDescriptor(name=param.name, description=text, read_only=param.read_only)
    constraints = param.constraints_text()
    if constraints:
        desc.additional_constraints = constraints
    if param.range is not None:
        lo, hi = param.range
        if param.item_type == "double":
            desc.floating_point_range = [FloatingPointRange(from_value=float(lo), to_value=float(hi), step=0.0)]
        else:
            desc.integer_range = [IntegerRange(from_value=int(lo), to_value=int(hi), step=0)]
    return desc


class NodeParameters(Mapping[str, Any]):
    """The declared parameters of one node (a read-only mapping name -> current value).

    Parameters
    ----------
    node : rclpy.node.Node
    schema : NodeSchema
    """

    def __init__(self, node, schema: NodeSchema) -> None:
        self.node = node
        self.schema = schema
        self._values: dict[str, Any] = {}
        self._hooks: dict[str, ApplyHook] = {}
        #: run-time sets refused so far (for diagnostics and tests)
        self.refused = 0
        node.add_on_set_parameters_callback(self._on_set)
        if hasattr(node, "add_pre_set_parameters_callback"):
            node.add_pre_set_parameters_callback(self._widen)

    # --------------------------------------------------------------- mapping
    def __getitem__(self, name: str) -> Any:
        return self._values[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._values)

    def __len__(self) -> int:
        return len(self._values)

    # ----------------------------------------------------------- declaration
    def declare(self, name: str, *, robot: Any = None, default: Any = None,
                resolve: Callable[[Any], Any] | None = None) -> Any:
        """Declare one parameter of the schema and return its value, checked.

        Parameters
        ----------
        name : str
        robot : RobotDescription, optional
            For a parameter whose default is a robot description key.
        default : Any, optional
            For a parameter whose default the node derives (``derived`` in the schema).
        resolve : callable, optional
            Turns the given value (override or default) into the value used,
            before it is declared, so the parameter reads what the node uses
            (``model_path: ''`` reads the default file's path).

        Raises
        ------
        ConfigError
            Naming the parameter: a start-up value of the wrong type, out of
            range, not among the choices or refused by its check; a robot
            description value the schema refuses.
        """
        from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
        from rclpy.parameter import Parameter

        param = self.schema[name]
        if name in self._values:
            raise ValueError(f"{self.schema.executable}: parameter {name!r} declared twice")
        value = self._default(param, robot, default)
        # rclpy takes a start-up override as is: an integer for a double parameter (``length_s: 3`` in a
        # parameters file) would be a type error.  Widen it first (rclpy keeps overrides in this dict).
        overrides = getattr(self.node, "_parameter_overrides", {})
        given = overrides.get(name)
        if given is not None and param.item_type == "double":
            if given.type_ == Parameter.Type.INTEGER:
                given = overrides[name] = Parameter(name, Parameter.Type.DOUBLE, float(given.value))
            elif given.type_ == Parameter.Type.INTEGER_ARRAY:
                given = overrides[name] = Parameter(name, Parameter.Type.DOUBLE_ARRAY, [float(v) for v in given.value])
        if resolve is not None:
            if given is not None and given.type_.value == getattr(Parameter.Type, param.type.upper()).value:
                overrides[name] = Parameter(name, value=resolve(given.value))
            value = resolve(value)
        try:
            declared = self.node.declare_parameter(name, value, parameter_descriptor(param)).value
        except InvalidParameterTypeException as exc:
            raise ConfigError(f"expects a {param.type.replace('_', ' ')}: {exc}", key=name) from None
        except InvalidParameterValueException as exc:
            raise ConfigError(f"out of range ({describe_range(param)}): {exc}", key=name) from None
        if isinstance(declared, tuple) or (param.type.endswith("_array") and not isinstance(declared, list)):
            declared = list(declared)
        self._values[name] = check_value(param, declared)
        return self._values[name]

    def _default(self, param: Param, robot: Any, default: Any) -> Any:
        if param.robot is not None:
            if robot is None:
                raise ValueError(f"{self.schema.executable}: {param.name} needs the robot description")
            value = robot_value(robot, param.robot)
            try:
                return check_value(param, value)
            except ConfigError as exc:
                source = getattr(robot, "source", "") or getattr(robot, "name", "")
                raise ConfigError(f"the robot description's value is refused by the node: {exc}",
                                  key=param.robot, source=source) from None
        if param.like is not None:
            return self._values[param.like]
        if param.derived is not None:
            if default is None:
                raise ValueError(f"{self.schema.executable}: {param.name} needs its derived default "
                                 f"({param.derived})")
            return default
        return param.default

    def declare_all(self, *, robot: Any = None, defaults: Mapping[str, Any] | None = None,
                    resolve: Mapping[str, Callable[[Any], Any]] | None = None, skip: tuple[str, ...] = ()) -> None:
        """Declare every parameter of the schema not declared yet (but ``skip``), in schema order."""
        defaults = defaults or {}
        resolve = resolve or {}
        for p in self.schema:
            if p.name not in self._values and p.name not in skip:
                self.declare(p.name, robot=robot, default=defaults.get(p.name), resolve=resolve.get(p.name))

    def on_set(self, hook: str, fn: ApplyHook) -> None:
        """Register the apply hook ``hook`` (a name the schema's ``apply`` fields use)."""
        if hook not in self.schema.apply_groups():
            raise ValueError(f"{self.schema.executable}: no parameter applies through {hook!r} "
                             f"(hooks: {', '.join(self.schema.apply_groups()) or 'none'})")
        self._hooks[hook] = fn

    def finish(self) -> None:
        """After the constructor declared everything: every hook registered, unknown start-up parameters logged.

        Raises
        ------
        ValueError
            For a schema parameter never declared or a hook never registered
            (a node that does not match its schema).
        """
        missing = [n for n in self.schema.names if n not in self._values]
        hooks = [h for h in self.schema.apply_groups() if h not in self._hooks]
        if missing or hooks:
            raise ValueError(f"{self.schema.executable} does not match its schema: undeclared {missing}, "
                             f"apply hooks not registered {hooks}")
        overrides = getattr(self.node, "_parameter_overrides", {})
        unknown = sorted(n for n in overrides if not self.node.has_parameter(n))
        if unknown:
            self.node.get_logger().error(f"ignoring parameters this node does not declare: {', '.join(unknown)} "
                                         f"(see docs/nodes.md)")

    # ------------------------------------------------------------- run time
    def _widen(self, parameters: list) -> list:
        """Pre-set hook: an integer for a double (``ros2 param set ... 3``) becomes the float."""
        from rclpy.parameter import Parameter

        out = []
        for p in parameters:
            param = self.schema.get(p.name)
            if param is not None and param.type == "double" and p.type_ == Parameter.Type.INTEGER:
                p = Parameter(p.name, Parameter.Type.DOUBLE, float(p.value))
            out.append(p)
        return out

    def _on_set(self, parameters: list):
        from rcl_interfaces.msg import SetParametersResult

        try:
            changes, applies = self._check(parameters)
        except (ConfigError, ValueError) as exc:
            self.refused += 1
            return SetParametersResult(successful=False, reason=str(exc))
        except Exception as exc:  # noqa: BLE001 - a check that fails is a refusal, never the end of the node
            self.refused += 1
            self.node.get_logger().error(f"checking a parameter set failed: {exc!r}\n{traceback.format_exc()}")
            return SetParametersResult(successful=False, reason=f"refused: the check failed ({exc!r})")
        if not changes:
            return SetParametersResult(successful=True)
        try:
            for apply in applies:
                apply()
        except Exception as exc:  # noqa: BLE001 - the node keeps running; say what happened
            self.refused += 1
            self.node.get_logger().error(f"applying {', '.join(changes)} failed: {exc!r}\n{traceback.format_exc()}")
            return SetParametersResult(successful=False, reason=f"refused: applying it failed ({exc!r})")
        self._values.update(changes)
        self.node.get_logger().info("parameter set: " + ", ".join(f"{k} = {_short(v)}" for k, v in changes.items()))
        return SetParametersResult(successful=True)

    def _check(self, parameters: list) -> tuple[dict[str, Any], list[Callable[[], None]]]:
        """Every parameter of a request checked, then every hook it touches; nothing applied yet."""
        changes: dict[str, Any] = {}
        for p in parameters:
            param = self.schema.get(p.name)
            if param is None or p.name not in self._values:
                continue  # being declared (checked by declare), or not ours (use_sim_time)
            if param.read_only:
                raise ConfigError("is read-only: it is set at start (restart the node with the new value)",
                                  key=p.name)
            changes[p.name] = check_value(param, p.value)
        merged = {**self._values, **changes}
        applies = []
        touched = dict.fromkeys(self.schema[n].apply for n in changes if self.schema[n].apply is not None)
        for hook in touched:
            names = frozenset(n for n in changes if self.schema[n].apply == hook)
            apply = self._hooks[hook](merged, names)
            if apply is not None:
                applies.append(apply)
        return changes, applies


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 80 else text[:60] + f"... ({len(text)} characters)"
