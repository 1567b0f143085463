"""Parameters of ``biotac_driver``: BioTac fingertips -> ``BioTacFrameBatch``."""

from __future__ import annotations

from .driver import MAX_FORCE_N, driver_params
from .schema import NodeSchema, Param

__all__ = ["BIOTAC_DRIVER", "TRANSPORTS"]

TRANSPORTS = ("cheetah", "serial", "simulated", "loopback")

BIOTAC_DRIVER = NodeSchema("biotac_driver", driver_params(
    kind="BioTac", transports=TRANSPORTS, transport="cheetah",
    transport_text="device transport: cheetah (Total Phase USB-SPI), serial (our USB bridge), simulated (sim.scene), "
                   "loopback (tests)",
    serial_port="/dev/ttyACM0", baudrate=921600, frames_depth=50,
    tare_on_start="baseline from the first frames (nothing is published before it; 0 = off)",
    tare_window="the last frames ~/tare takes the resting level over",
    tare_window_tunable_text="; tare.track_band_n follows it unless set",
    specific=(
        Param("frame_pattern", "string", "frame pattern: default, paper_50hz, biotac_sp, or a channel list "
              "(\"E1 PAC E2 PAC ...\")", default="default", max_chars=1024),
        Param("word_rate_hz", "double", "SPI word slots per second (PAC 2.2 kHz, frames 100 Hz by default)",
              default=4400.0, unit="Hz", range=(1.0, 1_000_000.0)),
        Param("batch_frames", "integer", "frames per message", default=10, range=(1, 10_000), unit="frames"),
        Param("wire", "string", "framing on the transport: spi (the driver runs the SPI sampling), bridge (our "
              "serial framing); auto = spi for cheetah, bridge otherwise", default="auto",
              choices=("auto", "spi", "bridge")),
        Param("pdc_pa_per_count", "double", "static pressure scale (0 = not calibrated)", default=0.0,
              unit="Pa/count", range=(0.0, 1e6)),
        Param("cheetah.port", "integer", "Cheetah adapter port (-1 = the first free one)", default=-1,
              range=(-1, 1023)),
        Param("cheetah.bitrate_khz", "integer", "SPI clock of the Cheetah adapter", default=4400,
              range=(1, 100_000), unit="kHz"),
    ),
    tare=(
        Param("tare.track_s", "double", "the PDC baseline follows drift with this time constant while the force is "
              "below tare.track_band_n (0 = tare only at start and on ~/tare)", default=0.5, unit="s",
              range=(0.0, 3600.0), tunable=True, apply="tracking"),
        Param("tare.track_band_n", "double", "baseline tracking only while |force| is below this (a touch freezes "
              "the baseline)", like="contact.force_threshold_n", unit="N", range=(0.0, MAX_FORCE_N), tunable=True,
              apply="tracking"),
    ),
))
