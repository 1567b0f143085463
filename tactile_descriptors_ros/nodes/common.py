"""Shared pieces of the nodes: parameters, ``/diagnostics``, rates, ``main``.

``diagnostic_updater`` is not available as a wheel, so :class:`Diagnostics`
is a small equivalent: tasks registered by name, each returning a
:class:`Status`, published together as one ``diagnostic_msgs/DiagnosticArray``
on ``/diagnostics`` every ``diagnostics_period_s`` of wall time (a steady
clock, so diagnostics keep flowing under ``use_sim_time`` with no ``/clock``).
Status names follow the ROS convention ``"<node name>: <task>"``.
"""

from __future__ import annotations

import collections
import gc
import math
import sys
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from ..errors import ConfigError, TactileError

__all__ = [
    "Status",
    "Diagnostics",
    "RateMeter",
    "declare",
    "parameter_descriptor",
    "check_value",
    "ParameterSetter",
    "setter_of",
    "unknown_overrides",
    "report_unknown_overrides",
    "CHOICES_PREFIX",
    "steady_clock",
    "run_node",
]

_LEVELS = {"ok": 0, "warn": 1, "error": 2, "stale": 3}


@dataclass
class Status:
    """One diagnostic status: level (ok, warn, error, stale), message, key/values."""

    level: str
    message: str
    values: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.level not in _LEVELS:
            raise ValueError(f"diagnostic level must be one of {tuple(_LEVELS)}, got {self.level!r}")


class RateMeter:
    """Events per second over a sliding window of wall time (a steady clock).

    Thread-safe: a driver's reader thread adds while the executor's
    diagnostics timer reads (a deque iterated while another thread appends
    raises, and the diagnostics task would report a failure instead of the
    rates).

    Parameters
    ----------
    window_s : float
        Length of the averaging window.
    now : callable, optional
        Clock in seconds (``time.monotonic``); injectable for tests.
    """

    def __init__(self, window_s: float = 2.0, now: Callable[[], float] = time.monotonic) -> None:
        self.window_s = float(window_s)
        self._now = now
        self._events: collections.deque[tuple[float, int]] = collections.deque()
        self._lock = threading.Lock()
        self._in_window = 0  # sum of the counts in _events, kept as they come and go (a read is O(1))
        self.total = 0

    def add(self, count: int = 1) -> None:
        t = self._now()
        with self._lock:
            self._events.append((t, int(count)))
            self._in_window += int(count)
            self.total += int(count)
            self._expire(t)

    def _expire(self, t: float) -> None:
        while self._events and self._events[0][0] < t - self.window_s:
            self._in_window -= self._events.popleft()[1]

    @property
    def rate_hz(self) -> float:
        t = self._now()
        with self._lock:
            self._expire(t)
            return self._in_window / self.window_s


def steady_clock():
    """An rclpy steady clock (timers on it run on wall time, also under ``use_sim_time``)."""
    from rclpy.clock import Clock, ClockType

    return Clock(clock_type=ClockType.STEADY_TIME)


class Diagnostics:
    """Publish named diagnostic tasks on ``/diagnostics``.

    Parameters
    ----------
    node : rclpy.node.Node
    period_s : float
        Publication period (wall time).
    hardware_id : str
        ``hardware_id`` of every status (e.g. the serial port or CAN channel).
    """

    def __init__(self, node, period_s: float = 1.0, hardware_id: str = "") -> None:
        from diagnostic_msgs.msg import DiagnosticArray

        self.node = node
        self.hardware_id = hardware_id
        self._tasks: list[tuple[str, Callable[[], Status]]] = []
        self._pub = node.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self._timer = node.create_timer(float(period_s), self.publish, clock=steady_clock())
        self.last: list[Any] = []

    def add(self, task: str, fn: Callable[[], Status]) -> None:
        """Register a task; ``fn`` is called at every publication."""
        self._tasks.append((task, fn))

    def statuses(self) -> list:
        """The current ``DiagnosticStatus`` messages (a failing task reports ERROR, not silence)."""
        from diagnostic_msgs.msg import DiagnosticStatus, KeyValue

        out = []
        for task, fn in self._tasks:
            try:
                st = fn()
            except Exception as exc:  # noqa: BLE001 - a broken task must show up, not stop the node
                st = Status("error", f"diagnostic task failed: {exc!r}")
            msg = DiagnosticStatus()
            msg.level = bytes([_LEVELS[st.level]])
            msg.name = f"{self.node.get_name()}: {task}"
            msg.message = st.message
            msg.hardware_id = self.hardware_id
            msg.values = [KeyValue(key=str(k), value=_fmt(v)) for k, v in st.values.items()]
            out.append(msg)
        return out

    def publish(self) -> None:
        from diagnostic_msgs.msg import DiagnosticArray

        arr = DiagnosticArray()
        arr.header.stamp = self.node.get_clock().now().to_msg()
        arr.status = self.statuses()
        self.last = arr.status
        self._pub.publish(arr)


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.6g}"
    return str(v)


#: what ``additional_constraints`` of a choice parameter starts with (``ros2 param describe`` shows it)
CHOICES_PREFIX = "one of: "
_INT_MAX = 2**63 - 1


def parameter_descriptor(name: str, default: Any, description: str, *, choices: Sequence[Any] | None = None,
                         minimum: float | None = None, maximum: float | None = None, read_only: bool = True):
    """A ``ParameterDescriptor``: description, range (``FloatingPointRange``/``IntegerRange``), choices, read-only.

    A range is given for a number with a ``minimum`` or ``maximum`` (the open
    side is the type's limit); choices go to ``additional_constraints`` as
    ``"one of: a, b"`` (ROS 2 has no field for them; the nodes enforce them).
    """
    from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor

    desc = ParameterDescriptor(name=name, description=description, read_only=read_only)
    if choices:
        desc.additional_constraints = CHOICES_PREFIX + ", ".join(map(str, choices))
    if (minimum is not None or maximum is not None) and not isinstance(default, bool):
        if isinstance(default, float):
            desc.floating_point_range = [FloatingPointRange(
                from_value=float(minimum) if minimum is not None else -float("inf"),
                to_value=float(maximum) if maximum is not None else float("inf"), step=0.0)]
        elif isinstance(default, int):
            desc.integer_range = [IntegerRange(
                from_value=int(minimum) if minimum is not None else -_INT_MAX - 1,
                to_value=int(maximum) if maximum is not None else _INT_MAX, step=0)]
    return desc


def check_value(name: str, value: Any, default: Any, *, choices: Sequence[Any] | None = None,
                minimum: float | None = None, maximum: float | None = None) -> Any:
    """``value`` checked against the type of ``default``, ``choices`` and the range; an int widens to float.

    Raises
    ------
    ConfigError
        Naming the parameter.
    """
    if isinstance(default, bool) and not isinstance(value, bool):
        raise ConfigError(f"must be true or false, got {value!r}", key=name)
    if isinstance(default, float) and isinstance(value, int) and not isinstance(value, bool):
        value = float(value)
    if isinstance(value, float) and not math.isfinite(value):  # NaN passes every comparison below
        raise ConfigError(f"must be a finite number, got {value!r}", key=name)
    if choices is not None and value not in choices:
        raise ConfigError(f"must be one of {tuple(choices)}, got {value!r}", key=name)
    if minimum is not None and (not isinstance(value, (int, float)) or value < minimum):
        raise ConfigError(f"must be at least {minimum}, got {value!r}", key=name)
    if maximum is not None and (not isinstance(value, (int, float)) or value > maximum):
        raise ConfigError(f"must be at most {maximum}, got {value!r}", key=name)
    return value


def _note_interrupts() -> Callable[[], bool]:
    """Make SIGINT only *noted* by Python; return "did it come?".

    ``rclpy.init`` installs rclpy's own handler for SIGINT and SIGTERM, which
    shuts the contexts down (the executor then returns from ``spin``) and
    then calls the Python handler found at ``init``.  Python's default one
    raises ``KeyboardInterrupt`` at whatever bytecode the main thread runs
    next -- inside a callback, a thread join, or a ``__del__`` (where Python
    can only print "Exception ignored in ..."); a second Ctrl-C (the terminal
    sends one to the process group and ``ros2 launch`` forwards another) would
    cut the clean-up short the same way.  So the handler installed here raises
    nothing: shutdown goes through rclpy's path alone, and every callback,
    ``close()`` and destructor runs to its end.  The returned function tells
    whether SIGINT came (a call that failed because the context was shut down
    under it is then a clean stop, not a fault).
    """
    import signal

    interrupted = threading.Event()
    if threading.current_thread() is not threading.main_thread():
        return interrupted.is_set  # signal handlers can be set only from the main thread

    def handler(signum, frame):
        interrupted.set()

    signal.signal(signal.SIGINT, handler)
    return interrupted.is_set


class ParameterSetter:
    """``ros2 param set`` for a node's writable parameters: checked, then applied, or refused with a reason.

    One per node (:func:`setter_of`).  :func:`declare` registers a writable
    parameter with an ``on_set`` function (one value) or an ``on_set_group``
    function (the values of all parameters of the request that share that
    function, as ``{name: value}``: settings that are only valid together,
    like a window length and hop, are checked together).  A set request is
    checked (type, choices, range, then the functions' own checks) for every
    parameter of the request before any is applied, so an atomic request is
    applied whole or not at all.  The functions raise
    :class:`~tactile_descriptors_ros.errors.ConfigError` (or ``ValueError``)
    to refuse, or return a function that applies the value(s).

    An integer for a ``double`` parameter (``ros2 param set ... 3``) is
    widened to a float before ROS checks the type, where rclpy offers the
    hook for it (pre-set callbacks, Iron and later).
    """

    def __init__(self, node) -> None:
        self.node = node
        self._rules: dict[str, tuple[Any, dict, Callable | None, Callable | None]] = {}
        self._doubles: set[str] = set()
        node.add_on_set_parameters_callback(self._on_set)
        if hasattr(node, "add_pre_set_parameters_callback"):
            node.add_pre_set_parameters_callback(self._widen)

    def add(self, name: str, default: Any, checks: dict, on_set: Callable | None = None,
            on_set_group: Callable | None = None) -> None:
        """Make ``name`` writable (see the class docstring)."""
        if (on_set is None) == (on_set_group is None):
            raise ValueError("give exactly one of on_set and on_set_group")
        self._rules[name] = (default, checks, on_set, on_set_group)

    def track_double(self, name: str) -> None:
        """Widen integers set on ``name`` to floats."""
        self._doubles.add(name)

    def _widen(self, parameters: list) -> list:
        from rclpy.parameter import Parameter

        out = []
        for p in parameters:
            if p.name in self._doubles and p.type_ == Parameter.Type.INTEGER:
                p = Parameter(p.name, Parameter.Type.DOUBLE, float(p.value))
            out.append(p)
        return out

    def _on_set(self, parameters: list):
        from rcl_interfaces.msg import SetParametersResult

        applies: list[tuple[str, Callable[[], None] | None]] = []
        groups: dict[int, tuple[Callable, dict[str, Any]]] = {}
        try:
            for p in parameters:
                rule = self._rules.get(p.name)
                if rule is None:
                    continue  # read-only ones are refused by ROS; declarations pass through
                default, checks, on_set, on_set_group = rule
                value = check_value(p.name, p.value, default, **checks)
                if on_set is not None:
                    applies.append((f"{p.name} = {value!r}", on_set(value)))
                else:
                    groups.setdefault(id(on_set_group), (on_set_group, {}))[1][p.name] = value
            for fn, values in groups.values():
                applies.append((", ".join(f"{k} = {v!r}" for k, v in values.items()), fn(values)))
        except (ConfigError, ValueError) as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        for text, apply in applies:
            if apply is not None:
                apply()
            self.node.get_logger().info(f"parameter set: {text}")
        return SetParametersResult(successful=True)


def setter_of(node) -> ParameterSetter:
    """The node's :class:`ParameterSetter` (created on first use)."""
    setter = getattr(node, "_tactile_parameter_setter", None)
    if setter is None:
        setter = ParameterSetter(node)
        node._tactile_parameter_setter = setter
    return setter


def declare(node, name: str, default: Any, description: str, *, choices: Sequence[Any] | None = None,
            minimum: float | None = None, maximum: float | None = None, read_only: bool = True,
            on_set: Callable[[Any], Callable[[], None] | None] | None = None,
            on_set_group: Callable[[dict[str, Any]], Callable[[], None] | None] | None = None,
            resolve: Callable[[Any], Any] | None = None) -> Any:
    """Declare a parameter with its ``ParameterDescriptor`` and return its value, validated.

    Parameters
    ----------
    node : rclpy.node.Node
    name, default, description
        As for ``declare_parameter``; the type is the default's.
    choices : sequence, optional
        Allowed values (``additional_constraints``).
    minimum, maximum : float, optional
        Range (``FloatingPointRange`` / ``IntegerRange``: ``ros2 param describe`` shows it).
    read_only : bool
        Read-only unless ``on_set`` or ``on_set_group`` is given.
    on_set : callable, optional
        Makes the parameter writable at run time (``ros2 param set``):
        ``on_set(value)`` gets a checked value and raises
        :class:`~tactile_descriptors_ros.errors.ConfigError` to refuse it, or
        returns a function applying it (see :class:`ParameterSetter`).
    on_set_group : callable, optional
        The same for parameters checked together: ``on_set_group({name: value})``.
    resolve : callable, optional
        Turns the given value (override or default) into the value used,
        before it is declared, so the parameter reads what the node uses
        (``model_path: ''`` reads the default file's path).

    Raises
    ------
    ConfigError
        Naming the parameter, for a value of the wrong type, not among
        ``choices`` or outside the range.
    """
    from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
    from rclpy.parameter import Parameter

    checks = {"choices": choices, "minimum": minimum, "maximum": maximum}
    extra = f" (one of: {', '.join(map(str, choices))})" if choices else ""
    writable = on_set is not None or on_set_group is not None
    descriptor = parameter_descriptor(name, default, description + extra, choices=choices, minimum=minimum,
                                      maximum=maximum, read_only=read_only and not writable)
    # rclpy takes a start-up override as is: an integer for a double parameter (``length_s: 3`` in a
    # parameters file) would be a type error.  Widen it first (rclpy keeps overrides in this dict).
    overrides = getattr(node, "_parameter_overrides", {})
    given = overrides.get(name)
    if isinstance(default, float) and given is not None and given.type_ == Parameter.Type.INTEGER:
        given = overrides[name] = Parameter(name, Parameter.Type.DOUBLE, float(given.value))
    if resolve is not None:
        if given is not None and type(given.value) is type(default):
            overrides[name] = Parameter(name, value=resolve(given.value))
        default = resolve(default)
    try:
        value = node.declare_parameter(name, default, descriptor).value
    except InvalidParameterTypeException as exc:
        raise ConfigError(f"wrong type: {exc}", key=name) from None
    except InvalidParameterValueException as exc:
        raise ConfigError(f"out of range ({_range_text(minimum, maximum)}): {exc}", key=name) from None
    value = check_value(name, value, default, **checks)
    if isinstance(default, float):
        setter_of(node).track_double(name)
    if writable:
        setter_of(node).add(name, default, checks, on_set, on_set_group)
    return value


def _range_text(minimum: float | None, maximum: float | None) -> str:
    lo = "-inf" if minimum is None else f"{minimum:g}"
    hi = "inf" if maximum is None else f"{maximum:g}"
    return f"{lo} .. {hi}"


def unknown_overrides(node) -> list[str]:
    """Start-up parameter overrides of ``node`` that it never declared (a typo in a parameters file)."""
    overrides = getattr(node, "_parameter_overrides", {})
    return sorted(n for n in overrides if not node.has_parameter(n))


def report_unknown_overrides(node) -> None:
    """Log an error naming every override ``node`` ignores (a ROS 2 node otherwise ignores them silently)."""
    unknown = unknown_overrides(node)
    if unknown:
        node.get_logger().error(f"ignoring parameters this node does not declare: {', '.join(unknown)} "
                                f"(see docs/nodes.md)")


def run_node(factory: Callable[..., Any], args: Sequence[str] | None = None) -> int:
    """Create a node, spin it until Ctrl-C or shutdown, then clean up.

    Ctrl-C (SIGINT) and SIGTERM go through rclpy's own shutdown path: its
    handler shuts the context down and ``spin`` returns; nothing is raised
    into the running code (:func:`_note_interrupts`).  A
    :class:`~tactile_descriptors_ros.errors.TactileError` raised while
    building or spinning the node (misconfiguration, a device that cannot be
    opened) is logged as a fatal error under the node's own logger (its name
    after remapping, also when the constructor failed half-way) and gives
    exit code 2 -- a clear message instead of a traceback.  The node's
    ``close()`` (if any) runs on every exit path once the node was built, so
    devices are closed and models saved.
    """
    import rclpy
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor

    interrupted = _note_interrupts()
    rclpy.init(args=list(args) if args is not None else sys.argv)
    node = None  # also a node whose constructor failed half-way: its logger has the node's name
    built = False
    code = 0
    try:
        if isinstance(factory, type):
            node = factory.__new__(factory)
            node.__init__()
        else:
            node = factory()
        built = True
        if rclpy.ok():  # a Ctrl-C during construction has shut the context down already
            executor = SingleThreadedExecutor()
            executor.add_node(node)
            executor.spin()
    except ExternalShutdownException:
        pass
    except TactileError as exc:
        _logger_of(node, factory).fatal(str(exc))
        code = 2
    except Exception:
        if rclpy.ok() and not interrupted():
            raise
        # a call failed because Ctrl-C shut the context down under it: a clean stop
    finally:
        if node is not None and built:
            close = getattr(node, "close", None)
            if close is not None:
                try:
                    close()
                except Exception as exc:  # noqa: BLE001 - report, keep shutting down
                    _logger_of(node, factory).error(f"while closing: {exc!r}")
        if node is not None:
            try:
                node.destroy_node()
            except Exception:  # noqa: BLE001 - a constructor that failed before rclpy made the node
                pass
        rclpy.try_shutdown()
        _ignore_interrupts()
        # Everything is closed and saved: spare the exit a full garbage collection of the node's
        # heap (seconds for a window node holding 116 cells' buffers on a busy machine, which
        # ros2 launch would escalate to SIGTERM).
        gc.freeze()
    return code


def _logger_of(node: Any, factory: Callable[..., Any]):
    """The node's logger (named after the node as remapped); before rclpy made the node, one of its default name."""
    import inspect

    from rclpy.logging import get_logger

    try:
        return node.get_logger()
    except Exception:  # noqa: BLE001 - the constructor failed before Node.__init__ set the logger up
        pass
    try:
        name = inspect.signature(factory).parameters["node_name"].default
    except (KeyError, TypeError, ValueError):
        name = getattr(factory, "__name__", "node")
    return get_logger(str(name))


def _ignore_interrupts() -> None:
    """Ignore SIGINT from here on: the node has stopped, and at exit Python would reset SIGINT to its
    default (death by signal, which ``ros2 launch`` reports as a crash) unless it is ignored."""
    import signal
    import threading

    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
