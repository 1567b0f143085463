"""The parameter schema of a node: the one place a parameter is named, typed, bounded and described.

Modelled on generate_parameter_library's one file per node: each executable
has a :class:`NodeSchema` (``params/<executable>.py``) listing its
:class:`Param` s -- name, type, default, range or choices, unit, read-only
or tunable, description.  From it

* the node declares its parameters (:mod:`tactile_descriptors_ros.nodes.parameters`:
  a ``ParameterDescriptor`` with the description, a ``FloatingPointRange`` /
  ``IntegerRange``, the choices in ``additional_constraints``, ``read_only``)
  and checks every value set at start or at run time with :func:`check_value`;
* the launch files and ``tactile launch`` check a graph's parameters before
  anything starts (:mod:`tactile_descriptors_ros.launching.parameters`);
* ``docs/nodes.md``'s parameter tables are written (:mod:`.docs`; a test
  checks they are current).

The schema is Python rather than YAML because its choices and defaults are
the core's own constants (``WINDOW_MODES``, the robot description's defaults,
``PA_UPDATES``): a YAML file would copy them into a second home; shared
pieces (the drivers' common parameters, the three QoS parameters of an
endpoint) are function calls instead of an include mechanism; and a check
that needs code (a class name's characters, a frame id) is a function the
schema names, not a string looked up elsewhere.

A schema is checked when it is built (that is, when its module is imported,
by every node, launch file and test): an unknown type, a name given twice, a
number without a finite range, or a default outside its range or choices is
a :class:`~tactile_descriptors_ros.errors.SchemaError` naming the node and
the parameter.

Plain data: no rclpy import.
"""

from __future__ import annotations

import math
import re
import unicodedata
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

from ..errors import ConfigError, SchemaError

__all__ = [
    "TYPES",
    "NUMBER_TYPES",
    "INT64_MIN",
    "INT64_MAX",
    "MAX_STRING_CHARS",
    "MAX_ITEMS",
    "Param",
    "NodeSchema",
    "check_value",
    "robot_value",
    "robot_default",
    "describe_range",
]

#: Parameter types, as ``ros2 param describe`` prints them (lower case).
TYPES = ("bool", "integer", "double", "string", "bool_array", "integer_array", "double_array", "string_array")
#: Types whose values (or items) are numbers and so need a range.
NUMBER_TYPES = ("integer", "double", "integer_array", "double_array")
INT64_MIN, INT64_MAX = -(2**63), 2**63 - 1
#: Longest string accepted unless a parameter says otherwise [characters].
MAX_STRING_CHARS = 4096
#: Most items of an array parameter unless it says otherwise.
MAX_ITEMS = 10_000
_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*(\.[A-Za-z][A-Za-z0-9_]*)*$")
#: robot description sections whose values are node parameter defaults (see :func:`robot_value`)
_ROBOT_SECTIONS = ("contact", "window", "descriptor")


@dataclass(frozen=True)
class Param:
    """One parameter of a node.

    Exactly one of ``default``, ``robot``, ``like`` and ``derived`` says where
    the default comes from.

    Attributes
    ----------
    name : str
        Dotted ROS parameter name (``window.length_s``).
    type : str
        One of :data:`TYPES`.
    description : str
        What it does, for ``ros2 param describe`` and the docs (without the
        unit, range or choices: they are added from the other fields).
    default : Any
        A fixed default.
    robot : str, optional
        The default is the robot description's value of this key
        (``contact.force_threshold_n``); the robot description's own default
        for the key is the documented fallback (:func:`robot_default`).
    like : str, optional
        The default is this other parameter's value (declared before).
    derived : str, optional
        The node computes the default (and must pass it when it declares the
        parameter); this text says how, for the docs.
    unit : str
        Unit of the value (``s``, ``N``, ``Hz``), or ``""``.
    range : tuple of (number, number), optional
        Inclusive bounds of a number (of each item of a number array);
        required for every number type.
    choices : tuple, optional
        The allowed values of a string (of each item of a string array).
    tunable : bool
        Writable at run time (``ros2 param set``); read-only otherwise.
    apply : str, optional
        For a tunable parameter: the name of the node's hook that checks and
        applies it with the others of the same name, seeing the node's other
        values (a window length with its hop).  Without one, the node reads
        the current value where it uses it, and a set needs nothing else.
    check : callable, optional
        ``check(value)`` raises :class:`~tactile_descriptors_ros.errors.ConfigError`
        for a value of the right type and range that is still wrong (a frame
        id with blanks, an empty list).
    normalize : callable, optional
        Applied to a value before it is checked (``str.lower`` for QoS
        policy names).
    max_chars : int
        Longest string (or string item) accepted.
    max_items : int
        Most items of an array.
    """

    name: str
    type: str
    description: str
    default: Any = None
    robot: str | None = None
    like: str | None = None
    derived: str | None = None
    unit: str = ""
    range: tuple[float, float] | None = None
    choices: tuple[Any, ...] | None = None
    tunable: bool = False
    apply: str | None = None
    check: Callable[[Any], None] | None = None
    normalize: Callable[[Any], Any] | None = None
    max_chars: int = MAX_STRING_CHARS
    max_items: int = MAX_ITEMS

    @property
    def read_only(self) -> bool:
        """Not writable at run time."""
        return not self.tunable

    @property
    def item_type(self) -> str:
        """The type of one value (the item type of an array)."""
        return self.type[:-6] if self.type.endswith("_array") else self.type

    def constraints_text(self) -> str:
        """What ``additional_constraints`` says: choices (``one of: a, b``), string and array bounds."""
        parts = []
        if self.choices is not None:
            parts.append(("each " if self.type.endswith("_array") else "") + "one of: "
                         + ", ".join(map(str, self.choices)))
        if self.item_type == "string" and self.choices is None:
            parts.append(f"at most {self.max_chars} characters, no control characters")
        if self.type.endswith("_array"):
            parts.append(f"at most {self.max_items} items")
        return "; ".join(parts)


def describe_range(param: Param) -> str:
    """``0.001 .. 3600`` (``""`` without a range)."""
    if param.range is None:
        return ""
    lo, hi = param.range
    return f"{_num(lo)} .. {_num(hi)}"


def _num(x: float) -> str:
    if isinstance(x, int) and abs(x) >= 10_000:
        return f"{x:,}"
    return f"{x:g}" if isinstance(x, float) else str(x)


def check_value(param: Param, value: Any, *, node: str = "") -> Any:
    """``value`` checked completely against ``param``; returned normalized (an int widened for a double).

    Checks the type, that a double is finite, the range, the choices, a
    string's length and characters, an array's length, then the parameter's
    own ``check``.

    Parameters
    ----------
    param : Param
    value : Any
    node : str, optional
        Node name, prefixed to the key of the error.

    Raises
    ------
    ConfigError
        Keyed ``[node.]<parameter>``, saying what is wrong and what is accepted.
    """
    key = f"{node}.{param.name}" if node else param.name
    if param.normalize is not None and _is_type(value, param.type):
        value = param.normalize(value)
    if param.type.endswith("_array"):
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"expects a list of {param.item_type} values, got {_show(value)}", key=key)
        if len(value) > param.max_items:
            raise ConfigError(f"at most {param.max_items} items, got {len(value)}", key=key)
        value = [_check_item(param, v, key) for v in value]
    else:
        value = _check_item(param, value, key)
    if param.check is not None:
        try:
            param.check(value)
        except ConfigError as exc:
            raise ConfigError(_strip_key(exc), key=key) from None
    return value


def _strip_key(exc: ConfigError) -> str:
    text = str(exc)
    if exc.key:
        text = text.split(f"'{exc.key}': ", 1)[-1]
    return text


def _is_type(value: Any, kind: str) -> bool:
    if kind.endswith("_array"):
        return isinstance(value, (list, tuple)) and all(_is_type(v, kind[:-6]) for v in value)
    if kind == "bool":
        return isinstance(value, bool)
    if kind == "integer":
        return isinstance(value, int) and not isinstance(value, bool)
    if kind == "double":
        return isinstance(value, (int, float)) and not isinstance(value, bool)
    return isinstance(value, str)


def _show(value: Any) -> str:
    text = repr(value)
    return (text[:60] + f"... ({len(text)} characters)" if len(text) > 80 else text) + f" ({type(value).__name__})"


def _check_item(param: Param, value: Any, key: str) -> Any:
    kind = param.item_type
    if not _is_type(value, kind):
        raise ConfigError(f"expects {'an' if kind == 'integer' else 'a'} {kind}, got {_show(value)}", key=key)
    if kind == "double":
        value = float(value)
        if not math.isfinite(value):
            raise ConfigError(f"must be a finite number ({describe_range(param)}), got {value!r}", key=key)
    if param.range is not None and kind in ("integer", "double"):
        lo, hi = param.range
        if not lo <= value <= hi:
            unit = f" {param.unit}" if param.unit else ""
            raise ConfigError(f"must be within {describe_range(param)}{unit}, got {value!r}", key=key)
    if kind == "string":
        if len(value) > param.max_chars:
            raise ConfigError(f"at most {param.max_chars} characters, got {len(value)}", key=key)
        bad = next((c for c in value if unicodedata.category(c) == "Cc"), None)
        if bad is not None:
            raise ConfigError(f"must not hold control characters, got {bad!r} at {value.index(bad)}", key=key)
    if param.choices is not None and value not in param.choices:
        raise ConfigError(f"must be one of {', '.join(map(str, param.choices))}, got {_show(value)}", key=key)
    return value


# ----------------------------------------------------------------- robot
def _robot_specs() -> dict[str, type]:
    from ..core.robot import ContactSpec, DescriptorSpec, WindowSpec

    return {"contact": ContactSpec, "window": WindowSpec, "descriptor": DescriptorSpec}


def robot_default(key: str) -> Any:
    """The robot description's own default of ``key`` (``window.length_s`` -> 2.0): what a robot file that
    leaves it out gets.

    Raises
    ------
    KeyError
        For a key that is not a field of the description's ``contact``,
        ``window`` or ``descriptor`` section.
    """
    import dataclasses

    section, _, name = key.partition(".")
    spec = _robot_specs().get(section)
    fields = {f.name: f for f in dataclasses.fields(spec)} if spec is not None else {}
    if name not in fields:
        raise KeyError(key)
    f = fields[name]
    value = f.default if f.default is not dataclasses.MISSING else f.default_factory()  # type: ignore[misc]
    return list(value) if isinstance(value, tuple) else value


def robot_value(robot: Any, key: str) -> Any:
    """``robot``'s value of ``key`` (``contact.force_threshold_n``), tuples as lists (ROS arrays)."""
    section, _, name = key.partition(".")
    value = getattr(getattr(robot, section), name)
    return list(value) if isinstance(value, tuple) else value


# ---------------------------------------------------------------- schema
@dataclass(frozen=True)
class NodeSchema:
    """The parameters of one executable, in declaration order.

    Attributes
    ----------
    executable : str
        Console script (``window_node``); also the default node name.
    params : tuple of Param
    """

    executable: str
    params: tuple[Param, ...]
    _by_name: dict[str, Param] = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "params", tuple(self.params))
        by_name: dict[str, Param] = {}
        for p in self.params:
            self._validate(p, by_name)
            by_name[p.name] = p
        self._by_name.update(by_name)

    def _error(self, p: Param | str, message: str) -> SchemaError:
        name = p.name if isinstance(p, Param) else p
        return SchemaError(message, key=f"{self.executable}.{name}")

    def _validate(self, p: Param, earlier: dict[str, Param]) -> None:
        if not isinstance(p.name, str) or not _NAME.match(p.name):
            raise self._error(str(p.name), "not a valid ROS parameter name (letters, digits, '_', dots between)")
        if p.name in earlier:
            raise self._error(p, "named twice in the schema")
        if p.type not in TYPES:
            raise self._error(p, f"unknown type {p.type!r} (known: {', '.join(TYPES)})")
        if not p.description.strip():
            raise self._error(p, "has no description")
        sources = [s for s in ("robot", "like", "derived") if getattr(p, s) is not None]
        if p.default is not None:
            sources.append("default")
        if len(sources) != 1:
            raise self._error(p, f"needs exactly one of default, robot, like, derived (got {sources or 'none'})")
        if p.type in NUMBER_TYPES:
            if p.range is None:
                raise self._error(p, "a number needs a finite range")
            lo, hi = p.range
            if not all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in (lo, hi)):
                raise self._error(p, f"range {p.range!r} must be two finite numbers")
            if lo > hi:
                raise self._error(p, f"range {p.range!r} is empty")
            if p.item_type == "integer" and not (isinstance(lo, int) and isinstance(hi, int)
                                                 and INT64_MIN <= lo and hi <= INT64_MAX):
                raise self._error(p, f"range {p.range!r} of an integer must be 64-bit integers")
        elif p.range is not None:
            raise self._error(p, f"a {p.type} has no range")
        if p.choices is not None and p.item_type != "string":
            raise self._error(p, "choices are for strings")
        if p.apply is not None and not p.tunable:
            raise self._error(p, "a read-only parameter has no apply hook")
        if p.like is not None:
            other = earlier.get(p.like)
            if other is None:
                raise self._error(p, f"takes its default from {p.like!r}, which is not declared before it")
            if other.type != p.type:
                raise self._error(p, f"takes its default from {p.like!r}, a {other.type}")
        for what, value in self._static_defaults(p):
            try:
                check_value(p, value)
            except ConfigError as exc:
                raise self._error(p, f"{what} {value!r} is refused by its own schema: {_strip_key(exc)}") from None

    def _static_defaults(self, p: Param) -> Iterator[tuple[str, Any]]:
        if p.default is not None:
            yield "default", p.default
        if p.robot is not None:
            try:
                yield f"the robot description's default of {p.robot}", robot_default(p.robot)
            except KeyError:
                raise self._error(p, f"{p.robot!r} is not a key of the robot description's "
                                     f"{', '.join(_ROBOT_SECTIONS)} sections") from None

    # ------------------------------------------------------------- access
    def __getitem__(self, name: str) -> Param:
        return self._by_name[name]

    def __contains__(self, name: object) -> bool:
        return name in self._by_name

    def __iter__(self) -> Iterator[Param]:
        return iter(self.params)

    def get(self, name: str) -> Param | None:
        """The parameter named ``name``, or None."""
        return self._by_name.get(name)

    @property
    def names(self) -> tuple[str, ...]:
        """Parameter names in declaration order."""
        return tuple(p.name for p in self.params)

    def types(self) -> dict[str, str]:
        """Name -> type, the launch check's table."""
        return {p.name: p.type for p in self.params}

    def tunable(self) -> tuple[Param, ...]:
        """The parameters writable at run time."""
        return tuple(p for p in self.params if p.tunable)

    def apply_groups(self) -> dict[str, tuple[str, ...]]:
        """Apply hook name -> the parameters it checks and applies together."""
        out: dict[str, list[str]] = {}
        for p in self.params:
            if p.apply is not None:
                out.setdefault(p.apply, []).append(p.name)
        return {k: tuple(v) for k, v in out.items()}


def join(*parts: Sequence[Param] | Param) -> tuple[Param, ...]:
    """Parameters and lists of parameters as one tuple (a schema built from shared pieces)."""
    out: list[Param] = []
    for part in parts:
        out.extend([part] if isinstance(part, Param) else part)
    return tuple(out)
