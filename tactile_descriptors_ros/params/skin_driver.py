"""Parameters of ``skin_driver``: multimodal skin cells -> ``SkinPartFrames``."""

from __future__ import annotations

from .common import frames_serialized
from .driver import driver_params
from .schema import NodeSchema, Param

__all__ = ["SKIN_DRIVER", "TRANSPORTS"]

TRANSPORTS = ("can", "serial", "simulated", "loopback")

SKIN_DRIVER = NodeSchema("skin_driver", driver_params(
    kind="skin-cell", transports=TRANSPORTS, transport="can",
    transport_text="device transport: can (python-can), serial (pyserial), simulated (sim.scene), loopback (tests)",
    serial_port="/dev/ttyUSB0", baudrate=3_000_000, frames_depth=200,
    tare_on_start="force baseline from the first samples (0 = off)",
    tare_window="the last force samples ~/tare takes the resting level over",
    tare_window_tunable_text="",
    specific=(
        Param("batch_s", "double", "sample time per message (all cells of a body part)", default=0.05, unit="s",
              range=(0.001, 10.0)),
        Param("can.interface", "string", "python-can interface (virtual in tests)", default="socketcan",
              max_chars=256),
        Param("can.channel", "string", "python-can channel", default="can0", max_chars=256),
        Param("can.bitrate", "integer", "CAN bitrate (0 = leave as configured)", default=0,
              range=(0, 10_000_000), unit="bit/s"),
        Param("sim.wire", "string", "framing of the simulated bus: can (skin CAN layout) or serial (skin serial "
              "framing)", default="can", choices=("can", "serial")),
        frames_serialized("write SkinPartFrames as their CDR bytes"),
        Param("sim.loop", "bool", "play the scene over and over, simulated once (CAN only): a large skin at full "
              "rate for as long as wanted", default=False),
    ),
))
