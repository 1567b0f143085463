"""Parameters the device drivers share (``biotac_driver``, ``skin_driver``)."""

from __future__ import annotations

from ..topics import FRAMES_TOPIC
from .common import body_parts, diagnostics_period, qos, robot, topic_pattern
from .schema import Param

__all__ = ["driver_params", "MAX_FORCE_N", "MAX_BAUDRATE"]

#: a force no tactile sensor here measures [N]
MAX_FORCE_N = 1000.0
MAX_BAUDRATE = 100_000_000


def driver_params(*, kind: str, transports: tuple[str, ...], transport: str, transport_text: str,
                  serial_port: str, baudrate: int, frames_depth: int, tare_on_start: str, tare_window: str,
                  tare_window_tunable_text: str, specific: tuple[Param, ...],
                  tare: tuple[Param, ...] = ()) -> tuple[Param, ...]:
    """A driver's parameters: robot and body parts, transport, ``specific`` ones, stamps, tare (and its own
    ``tare`` ones, after F_t), simulation, QoS."""
    return (
        robot(),
        body_parts(f"every {kind} body part of the robot"),
        Param("transport", "string", transport_text, default=transport, choices=transports),
        *specific,
        Param("stamp_source", "string", "time stamps: clock (the device's sample clock carried to the node clock "
              "by an offset estimated from every read: when the sample was acquired, never in the future) or device "
              "(the device's time as it is: simulations, bridges synchronised to ROS time)",
              default="clock", choices=("clock", "device")),
        Param("resync_s", "double", "a device clock jump larger than this re-anchors the clock stamps' offset "
              "(0 = never)", default=1.0, unit="s", range=(0.0, 3600.0)),
        Param("tare_on_start_s", "double", f"{tare_on_start}; at most the samples the driver keeps (BioTac: "
              "2000 frames, 20 s at 100 frames/s; skin cell: 500 force samples, 2 s at 250 Hz)", default=0.5, unit="s",
              range=(0.0, 60.0)),
        Param("tare.window_s", "double", f"{tare_window}; applies to the next ~/tare; at most the samples the driver "
              "keeps (as tare_on_start_s)", default=0.2, unit="s", range=(0.01, 60.0), tunable=True, apply="tare"),
        Param("contact.force_threshold_n", "double", "contact gate F_t: ~/tare is refused at or above this force"
              f"{tare_window_tunable_text}", robot="contact.force_threshold_n", unit="N", range=(0.0, MAX_FORCE_N),
              tunable=True),
        *tare,
        topic_pattern(FRAMES_TOPIC),
        Param("serial.port", "string", "serial port or pyserial URL (loop:// in tests)", default=serial_port,
              max_chars=1024),
        Param("serial.baudrate", "integer", "baud rate of the serial port", default=baudrate,
              range=(1, MAX_BAUDRATE), unit="baud"),
        Param("sim.scene", "string", "scene played by the simulated transport (name or path)", default=""),
        Param("sim.speed", "double", "simulated time per wall time (a busy machine needs less than 1)", default=1.0,
              range=(0.001, 1000.0)),
        Param("autostart", "bool", "configure and activate at start (a device that cannot be opened ends the node "
              "with exit code 2)", default=True),
        diagnostics_period(),
        Param("reconnect_s", "double", "a lost device (every read fails) is closed and reopened this often",
              default=0.25, unit="s", range=(0.01, 3600.0)),
        Param("read_period_s", "double", "shortest time between two reads of the device: frames queue meanwhile and "
              "are decoded and published together (0 = read as soon as any is there); adds at most itself to the "
              "latency", default=0.0, unit="s", range=(0.0, 10.0)),
        *qos("frames", "reliable", "volatile", frames_depth),
    )
