"""What the device drivers share: robot selection, lifecycle, reader thread, transport diagnostics.

:class:`DriverBase` is the common base of
:class:`~tactile_descriptors_ros.nodes.biotac_driver.BiotacDriver` and
:class:`~tactile_descriptors_ros.nodes.skin_driver.SkinDriver`.  It owns the
transport and the reader thread; a subclass says how to build its simulated
source (:meth:`DriverBase._simulated_source`), how to read
(:meth:`DriverBase._read`) and handle (:meth:`DriverBase._consume`) a batch,
which publishers to create and destroy, and its own diagnostics.

Lifecycle: configure opens the device (:meth:`DriverBase._open_source` may
build a decoder on it), activate starts the reader thread, deactivate stops
it, cleanup closes the device and destroys the publishers.  A
:class:`~tactile_descriptors_ros.errors.TransportError` in the reader is
counted (``transport_errors``), any other exception too (``reader_errors``);
the thread waits 0.5 s and reads on.
"""

from __future__ import annotations

import threading
from collections import Counter
from collections.abc import Callable, Iterable
from typing import Any

from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn

from ..core.robot import RobotDescription, load_robot
from ..errors import ConfigError, TactileError, TransportError
from ..transports import create_transport
from .common import Diagnostics, Status, declare
from .window_node import message_kind, select_body_parts

__all__ = ["DriverBase"]


class DriverBase(LifecycleNode):
    """Base of the device drivers; ``kwargs`` go to :class:`rclpy.lifecycle.LifecycleNode`.

    Parameters
    ----------
    node_name : str
    transport_factory : callable, optional
        For tests: ``f(node) -> Transport`` replacing the ``transport`` parameter's backend.
    """

    #: name of the reader thread
    reader_thread_name = "reader"
    #: close a transport whose configure failed (else it is only dropped)
    close_on_failed_configure = True

    transport_name: str
    stamp_source: str
    sim_scene: str
    tp: dict[str, dict[str, Any]]

    def __init__(self, node_name: str, transport_factory=None, **kwargs) -> None:
        super().__init__(node_name, **kwargs)
        self._transport_factory = transport_factory
        self.transport = None
        self.faults: Counter[str] = Counter()
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.last_error: str | None = None

    # ---------------------------------------------------------- parameters
    def _declare_robot(self, kind: str, example: str, parts_what: str
                       ) -> tuple[RobotDescription, RobotDescription]:
        """Declare ``robot`` and ``body_parts``; return the full robot and the served body parts.

        Parameters
        ----------
        kind : str
            Message kind of the body parts served (``biotac`` or ``skin``).
        example : str
            Shipped robot named in the error when ``robot`` is missing.
        parts_what : str
            What the body parts are, for the error when the robot has none.
        """
        robot_arg = declare(self, "robot", "", "robot description: shipped name or YAML path")
        if not robot_arg:
            raise ConfigError(f"parameter 'robot' is required (e.g. {example} or a YAML path)", key="robot")
        full = load_robot(robot_arg)
        parts = [p.name for p in full.body_parts if message_kind(full.cell_types[p.cell_type]) == kind]
        if not parts:
            raise ConfigError(f"robot {full.name!r} has no {parts_what} body parts", key="body_parts")
        return full, select_body_parts(full, declare(self, "body_parts", parts, "body parts served"))

    def _declare_stamps_and_tare(self, contact_threshold_n: float, tare_on_start_what: str,
                                 tare_window_what: str) -> None:
        """Declare ``stamp_source``, ``resync_s``, ``tare_on_start_s``, ``tare.window_s``, ``contact_threshold_n``."""
        self.stamp_source = declare(self, "stamp_source", "clock", "time stamps", choices=("clock", "device"))
        self.resync_s = declare(self, "resync_s", 1.0, "re-anchor clock stamps beyond this drift [s] (0 = never)",
                                minimum=0.0)
        self.tare_on_start_s = declare(self, "tare_on_start_s", 0.5, tare_on_start_what, minimum=0.0)
        self.tare_window_s = declare(self, "tare.window_s", 0.2, tare_window_what, minimum=0.01)
        self.contact_threshold_n = declare(self, "contact_threshold_n", contact_threshold_n,
                                           "~/tare is refused at or above this force [N]", minimum=0.0)

    def _start(self, autostart: bool, tasks: Iterable[tuple[str, Callable[[], Status]]]) -> None:
        """Create ``~/tare`` and the diagnostics (``tasks``), then configure and activate if ``autostart``."""
        from std_srvs.srv import Trigger

        self.tare_srv = self.create_service(Trigger, "~/tare", self._srv_tare)
        self.diagnostics = Diagnostics(self, declare(self, "diagnostics_period_s", 1.0, "diagnostics period [s]",
                                                     minimum=0.01), hardware_id=self.transport_name)
        for name, task in tasks:
            self.diagnostics.add(name, task)
        if autostart:
            if self.trigger_configure() != TransitionCallbackReturn.SUCCESS:
                raise TransportError(f"configure failed: {self.last_error}")
            if self.trigger_activate() != TransitionCallbackReturn.SUCCESS:
                raise TransportError(f"activate failed: {self.last_error}")

    # ------------------------------------------------- subclass obligations
    def _simulated_source(self):
        """The source of the ``simulated`` transport (``sim.scene`` is set)."""
        raise NotImplementedError

    def _open_source(self) -> None:
        """After the transport opened: build what decodes it (may raise :class:`TactileError`)."""

    def _configured(self) -> TransitionCallbackReturn:
        """After a successful open: create state and publishers."""
        raise NotImplementedError

    def _destroy_publishers(self) -> None:
        """Destroy the lifecycle publishers made by :meth:`_configured`."""
        raise NotImplementedError

    def _read(self) -> list:
        """One read of the device (the reader thread's loop body)."""
        raise NotImplementedError

    def _consume(self, items: list) -> None:
        """Handle what one :meth:`_read` returned."""
        raise NotImplementedError

    def _srv_tare(self, request, response):
        raise NotImplementedError

    # ------------------------------------------------------------- lifecycle
    def _make_transport(self):
        if self._transport_factory is not None:
            return self._transport_factory(self)
        if self.transport_name == "simulated":
            if not self.sim_scene:
                raise ConfigError("transport 'simulated' needs the parameter sim.scene", key="sim.scene")
            return create_transport("simulated", source=self._simulated_source())
        if self.transport_name == "loopback":
            return create_transport("loopback", timeout_s=0.05)
        return create_transport(self.transport_name, **self.tp[self.transport_name])

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        try:
            self.transport = self._make_transport()
            self.transport.open()
            self._open_source()
        except TactileError as exc:
            self.last_error = str(exc)
            self.get_logger().error(f"cannot open {self.transport_name} transport: {exc}")
            if self.transport is not None and self.close_on_failed_configure:
                self.transport.close()
            self.transport = None
            return TransitionCallbackReturn.FAILURE
        return self._configured()

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, daemon=True, name=self.reader_thread_name)
        self._thread.start()
        return super().on_activate(state)

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._stop_thread()
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._stop_thread()
        self._close_transport()
        self._destroy_publishers()
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.close()
        return TransitionCallbackReturn.SUCCESS

    def close(self) -> None:
        """Stop reading and close the device (called on every exit path by ``main``)."""
        self._stop_thread()
        self._close_transport()

    def _stop_thread(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None

    def _close_transport(self) -> None:
        if self.transport is not None:
            try:
                self.transport.close()
            finally:
                self.transport = None

    # ---------------------------------------------------------------- reading
    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                items = self._read()
            except TransportError as exc:
                self.faults["transport_errors"] += 1
                self.last_error = str(exc)
                self.get_logger().error(f"transport: {exc}", throttle_duration_sec=5.0)
                self._stop.wait(0.5)
                continue
            except Exception as exc:  # noqa: BLE001 - report and keep the node alive
                self.faults["reader_errors"] += 1
                self.last_error = repr(exc)
                self.get_logger().error(f"reader: {exc!r}", throttle_duration_sec=5.0)
                self._stop.wait(0.5)
                continue
            self._consume(items)

    # ------------------------------------------------------------ diagnostics
    def _transport_values(self, settings: dict[str, Any]) -> dict[str, Any]:
        """Key/values of the transport status: name, ``settings``, stamp source, device description, faults."""
        values = {"transport": self.transport_name, **settings, "stamp_source": self.stamp_source}
        if self.transport is not None:
            values.update({f"device_{k}": v for k, v in self.transport.describe().items()})
        values.update(dict(self.faults))
        return values

    def _transport_error(self, values: dict[str, Any]) -> Status | None:
        """The error status of a closed transport or one with reader faults; ``None`` when neither."""
        if self.transport is None:
            return Status("error", f"not open{': ' + self.last_error if self.last_error else ''}", values)
        if self.faults.get("transport_errors") or self.faults.get("reader_errors"):
            return Status("error", self.last_error or "transport errors", values)
        return None
