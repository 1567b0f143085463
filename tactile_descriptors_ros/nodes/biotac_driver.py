"""``biotac_driver``: BioTac fingertips -> ``BioTacFrameBatch`` (transport -> codec -> message).

Transports (parameter ``transport``):

* ``cheetah``   -- Total Phase Cheetah USB-SPI adapter; the driver runs the
  SPI sampling sequence itself (one frame of the frame pattern per read,
  every BioTac on the adapter by chip select) and paces it to ``word_rate_hz``;
* ``serial``    -- our USB-serial bridge (``docs/protocols.md``): framed,
  CRC-checked frames per chip select with sequence numbers and a bridge clock;
* ``loopback``  -- the bridge framing over an in-process loopback (tests);
* ``simulated`` -- a scene (``sim.scene``) played by the simulator, speaking the
  bridge framing (the real decoder and its fault counters are exercised).

Up to five BioTacs (chip selects 0..4) are mapped to body parts by the robot
description (``chip_select`` of each cell).  Each message carries
``batch_frames`` consecutive frames of one BioTac: full-rate PAC with
per-sample offsets, the slow channels once per frame.  A bad word (parity,
error word, missing) is ``INVALID_COUNT`` -- never the previous value, never
another finger's (each chip select's reply is decoded on its own).  A gap in
the frame sequence ends a batch, so the frames of one message are always
consecutive.

Time stamps (``stamp_source``): ``clock`` anchors the device's sample clock
(frame count on SPI, the bridge clock on serial) to the node clock at the
first frame and re-anchors when the two drift apart by more than
``resync_s``; ``device`` uses the device time as it is (simulations; bridges
synchronised to ROS time).

``~/tare`` (std_srvs/Trigger) sets the PDC and electrode baselines to their
resting level (:func:`~..core.tare.resting_level`) over the last
``tare.window_s`` of frames; it is refused while any BioTac reads a force
at or above the contact threshold.  With ``tare_on_start_s > 0`` the first
frames are used as the baseline (nothing is published before), so the force
of an untared sensor never reaches the window node.

The node is a lifecycle node (``rclpy.lifecycle``, ROS 2 Humble and later):
configure opens the device and reads serial numbers, activate starts the
reader thread, deactivate stops it, cleanup closes the device.  With
``autostart`` (default) it configures and activates itself at start.
"""

from __future__ import annotations

import time
from collections.abc import Sequence

from rclpy.lifecycle import TransitionCallbackReturn

from ..codecs.biotac_spi import MAX_SENSORS, BiotacFrameDecoder, FramePattern
from ..errors import ConfigError
from ..params.biotac_driver import BIOTAC_DRIVER
from ..streams.biotac import (
    RECENT_FRAMES,
    BiotacStream,
    BridgeFrameSource,
    ReadItem,
    SensorConfig,
    SensorState,
    SpiFrameSource,
)
from ..streams.frames import BioTacBatch
from .common import RateMeter, Status, run_node
from .conversions import biotac_batch_to_msg
from .driver_base import DriverBase

__all__ = ["BiotacDriver", "SensorConfig", "SpiFrameSource", "BridgeFrameSource", "main"]

class BiotacDriver(DriverBase):
    """The BioTac driver; ``kwargs`` go to :class:`rclpy.lifecycle.LifecycleNode`.

    Parameters
    ----------
    node_name : str
    transport_factory : callable, optional
        For tests: ``f(node) -> Transport`` replacing the ``transport`` parameter's backend.
    """

    reader_thread_name = "biotac-reader"

    def __init__(self, node_name: str = "biotac_driver", transport_factory=None, **kwargs) -> None:
        super().__init__(node_name, transport_factory, **kwargs)
        full, self.robot = self._declare_parameters(BIOTAC_DRIVER, "biotac", "shadow_hand", "BioTac")
        params = self.params
        self.pattern = FramePattern.parse(params["frame_pattern"])
        self.word_rate_hz = params["word_rate_hz"]
        self.batch_frames = params["batch_frames"]
        self.wire = params["wire"]
        self.pdc_pa_per_count = params["pdc_pa_per_count"]
        self.tp = {
            "cheetah": {"port": params["cheetah.port"], "bitrate_khz": params["cheetah.bitrate_khz"]},
            "serial": {"port": params["serial.port"], "baudrate": params["serial.baudrate"]},
        }
        params.on_set("tracking", self._retune_tracking)

        ct = self.robot.cell_types[self.robot.body_parts[0].cell_type]
        self.force_n_per_count = ct.force.n_per_count
        self.pac_pa_per_count = ct.vibration.si_per_count if ct.vibration.unit == "Pa" else 0.0
        self.sensors: dict[int, SensorConfig] = {}
        for part in self.robot.body_parts:
            for cell in part.cells:
                cs = cell.extra.get("chip_select")
                if not isinstance(cs, int) or isinstance(cs, bool) or not 0 <= cs < MAX_SENSORS:
                    raise ConfigError(f"BioTac {cell.name!r} needs a chip_select 0..{MAX_SENSORS - 1}, got {cs!r}",
                                      key=f"body_parts.{part.name}.cells.{cell.name}.chip_select")
                if cs in self.sensors:
                    raise ConfigError(f"chip select {cs} is used by {self.sensors[cs].sensor_name!r} and "
                                      f"{cell.name!r}", key=f"body_parts.{part.name}.cells.{cell.name}.chip_select")
                self.sensors[cs] = SensorConfig(cs, cell.name, part.name, str(cell.extra.get("frame_id", cell.name)))
        n_el = len(ct.deformation.channels)
        if self.pattern.electrode_count != n_el:
            raise ConfigError(f"frame pattern samples {self.pattern.electrode_count} electrodes but the robot's "
                              f"cell type has {n_el}", key="frame_pattern")

        self.source = None
        self.stream: BiotacStream | None = None
        self._rates: dict[int, tuple[RateMeter, RateMeter]] = {}
        self._last_frame: dict[int, float] = {}
        self.publishers_by_cs: dict[int, object] = {}
        self._start([("transport", self._transport_status)]
                    + [(cfg.sensor_name, lambda cs=cs: self._sensor_status(cs))
                       for cs, cfg in sorted(self.sensors.items())])

    def _tare_history(self) -> tuple[float, str]:
        frame_hz = self.pattern.rates(self.word_rate_hz).frame_rate_hz
        return RECENT_FRAMES / frame_hz, (f"{RECENT_FRAMES} frames at {frame_hz:g} frames/s from word_rate_hz and "
                                          "frame_pattern")

    def _track_alpha(self, track_s: float) -> float:
        """The weight of one frame in the baseline that follows drift with time constant ``track_s`` (0 = off)."""
        frame_hz = self.pattern.rates(self.word_rate_hz).frame_rate_hz
        return min(1.0, 1.0 / (frame_hz * track_s)) if track_s > 0 else 0.0

    def _retune_tracking(self, values, changed):
        """``ros2 param set ... tare.track_s / tare.track_band_n``: the running stream follows."""
        alpha, band_n = self._track_alpha(values["tare.track_s"]), values["tare.track_band_n"]

        def apply() -> None:
            if self.stream is not None:
                with self._lock:
                    self.stream.track_alpha = alpha
                    self.stream.track_band_n = band_n

        return apply

    # ------------------------------------------------------------- lifecycle
    def _simulated_source(self):
        from ..sim.sources import BiotacBridgeSource, load_scene_for

        scene = load_scene_for(self.sim_scene, self.robot.name)
        rates = self.pattern.rates(self.word_rate_hz)
        sim_hz = scene.robot.cell_types[self.robot.body_parts[0].cell_type].deformation.rate_hz
        if abs(rates.frame_rate_hz - sim_hz) > 1e-6 * sim_hz:
            raise ConfigError(f"the frame pattern at {self.word_rate_hz} words/s gives {rates.frame_rate_hz:.3f} "
                              f"frames/s; the scene simulates {sim_hz} frames/s", key="word_rate_hz")
        return BiotacBridgeSource(scene, self.pattern, speed=self.sim_speed, chip_selects=set(self.sensors),
                                  serial_prefix="BTSIM")

    def _open_source(self) -> None:
        decoder = BiotacFrameDecoder(self.pattern, sorted(self.sensors))
        wire = self.wire if self.wire != "auto" else ("spi" if self.transport_name == "cheetah" else "bridge")
        if wire == "spi":
            self.source = SpiFrameSource(self.transport, self.pattern, sorted(self.sensors), self.word_rate_hz,
                                         decoder)
        else:
            period_ns = 1e9 / self.pattern.rates(self.word_rate_hz).frame_rate_hz
            self.source = BridgeFrameSource(self.transport, self.pattern, sorted(self.sensors), decoder,
                                            frame_period_ns=period_ns)
        self.source.read_serial_numbers()
        for cs, err in self.source.serial_errors.items():
            self.get_logger().warning(f"{self.sensors[cs].sensor_name} (chip select {cs}): no serial number: {err}")

    def _reopened(self, gap_s: float) -> None:
        if isinstance(self.source, BridgeFrameSource):
            self.source.restart(self.transport)
        else:
            self.source.spi = self.transport
        with self._lock:
            pending = self.stream.resume(gap_s) if self.stream is not None else []
        for st, batch in pending:
            self._publish(st, batch)

    @property
    def state(self) -> dict[int, SensorState]:
        """Per chip select: pending frames, tare, counters (empty before configure)."""
        return self.stream.state if self.stream is not None else {}

    def _configured(self) -> TransitionCallbackReturn:
        self.stream = BiotacStream(
            self.sensors, self.pattern, self.word_rate_hz, self.batch_frames, self.stamp_source, self.resync_s,
            self.tare_on_start_s, self.params["tare.track_s"], self.params["tare.track_band_n"], self.force_n_per_count,
            lambda: self.get_clock().now().nanoseconds, self.faults, self._log_stream)
        self._rates = {cs: (RateMeter(), RateMeter()) for cs in self.sensors}
        self._last_frame = {}
        from tactile_descriptors_msgs.msg import BioTacFrameBatch

        topics = {}
        for cs, cfg in self.sensors.items():
            topic = self.topic_fmt.format(body_part=cfg.body_part)
            if topic not in topics:
                topics[topic] = self.create_lifecycle_publisher(BioTacFrameBatch, topic, self.qos_frames)
            self.publishers_by_cs[cs] = topics[topic]
        self.get_logger().info(
            f"{self.transport_name} transport open: {len(self.sensors)} BioTacs "
            f"({', '.join(f'{c.sensor_name}@cs{cs}' for cs, c in sorted(self.sensors.items()))}), pattern "
            f"{self.pattern.word_count} words, PAC {self.pattern.rates(self.word_rate_hz).pac_rate_hz:.0f} Hz")
        return TransitionCallbackReturn.SUCCESS

    def _destroy_publishers(self) -> None:
        for pub in set(self.publishers_by_cs.values()):
            self.destroy_lifecycle_publisher(pub)
        self.publishers_by_cs.clear()

    # ---------------------------------------------------------------- reading
    def _read(self) -> list[ReadItem]:
        return self.source.read()

    def _consume(self, items: list[ReadItem]) -> None:
        host = time.monotonic_ns()
        with self._lock:
            for item in items:
                rate, bad_rate = self._rates[item.chip_select]
                rate.add(len(item.frames))
                if item.frames.counts.bad:
                    bad_rate.add(item.frames.counts.bad)
                self._last_frame[item.chip_select] = host * 1e-9
            out = self.stream.add_read(items, host)
        for st, batch in out:
            self._publish(st, batch)

    def _log_stream(self, level: str, text: str) -> None:
        if level == "info":
            self.get_logger().info(text)
        else:
            self.get_logger().warning(text, throttle_duration_sec=5.0)

    def _publish(self, st: SensorState, batch: BioTacBatch) -> None:
        cfg = st.cfg
        msg = biotac_batch_to_msg(
            batch, sensor_name=cfg.sensor_name, body_part=cfg.body_part, chip_select=cfg.chip_select,
            serial_number=self.source.serial_numbers.get(cfg.chip_select, "") if self.source else "",
            frame_id=cfg.frame_id, pac_pa_per_count=self.pac_pa_per_count, pdc_pa_per_count=self.pdc_pa_per_count,
            force_n_per_count=self.force_n_per_count, pdc_tare_counts=st.tare_pdc if st.tared else 0.0,
            electrode_tare_counts=st.tare_electrodes if st.tare_electrodes is not None else ())
        pub = self.publishers_by_cs.get(cfg.chip_select)
        if pub is not None:
            pub.publish(msg)
            st.messages += 1

    # ------------------------------------------------------------------- tare
    def _srv_tare(self, request, response):
        with self._lock:
            if not self.state or all(not s.recent_pdc for s in self.state.values()):
                response.success, response.message = False, "no frames received yet (is the driver active?)"
                return response
            now = time.monotonic()
            # sensors that sent frames but none lately (one that never sent fails its own tare below)
            ages = {self.sensors[cs].sensor_name: now - t for cs, t in self._last_frame.items()}
            stale = [f"{name} {age:.1f} s ago" for name, age in ages.items() if age > self.stale_after_s]
            if stale:
                why = "the simulated scene has ended" if self.scene_ended() else "unplugged or stopped?"
                response.success = False
                response.message = (f"refused: stale frames (last frame {', '.join(stale)}; {why}); a tare needs "
                                    f"frames from the last {self.stale_after_s} s")
                return response
            touching = []
            for st in self.state.values():
                f = self.stream.force_now(st)
                if f is not None and f >= self.params["contact.force_threshold_n"]:
                    touching.append(f"{st.cfg.sensor_name} ({f:.2f} N)")
            if touching:
                response.success = False
                response.message = (f"refused: in contact: {', '.join(touching)}; release the fingers "
                                    f"(force < {self.params['contact.force_threshold_n']} N) and call ~/tare again")
                return response
            results = [self.stream.tare_one(st, self.params["tare.window_s"], check_contact=False)
                       for st in self.state.values()]
        response.success = all(ok for ok, _ in results)
        response.message = "; ".join(f"{st.cfg.sensor_name}: {why}" for st, (ok, why) in zip(self.state.values(),
                                                                                               results))
        self.get_logger().info(f"tare: {response.message}")
        return response

    # ------------------------------------------------------------ diagnostics
    def _transport_status(self) -> Status:
        values = self._transport_values({"frame_pattern": str(self.pattern), "word_rate_hz": self.word_rate_hz})
        src = self.source
        if isinstance(src, BridgeFrameSource):
            values.update({f"bridge_{k}": v for k, v in src.bridge.stats.as_dict().items()})
            for cs, n in src.unconfigured_frames.items():
                values[f"frames_from_unconfigured_cs{cs}"] = n
            values["payload_decode_errors"] = src.decode_errors
        elif isinstance(src, SpiFrameSource):
            values["schedule_overruns"] = src.overruns
        error = self._transport_error(values)
        if error is not None:
            return error
        if isinstance(src, BridgeFrameSource) and src.decode_errors:
            return Status("warn", f"{src.decode_errors} bridge payloads do not fit the frame pattern "
                                  f"{str(self.pattern)!r}: {src.last_decode_error}", values)
        if isinstance(src, BridgeFrameSource) and (src.bridge.stats.crc_errors or src.unconfigured_frames):
            return Status("warn", "bridge frames rejected (CRC errors or unconfigured chip selects)", values)
        return Status("ok", "open", values)

    def _sensor_status(self, cs: int) -> Status:
        cfg = self.sensors[cs]
        st = self.state.get(cs)
        serial = self.source.serial_numbers.get(cs, "") if self.source else ""
        values = {"chip_select": cs, "body_part": cfg.body_part, "serial_number": serial or "(unknown)"}
        if st is None:
            return Status("stale", "not configured", values)
        rates = self.pattern.rates(self.word_rate_hz)
        rate, bad_rate = self._rates[cs]
        fr = rate.rate_hz
        values.update({"frame_rate_hz": fr, "pac_rate_hz": fr * self.pattern.pac_count,
                       "expected_frame_rate_hz": rates.frame_rate_hz, "frames": st.frames_total,
                       "messages": st.messages, "lost_frames": st.lost_frames, "gaps": st.gaps,
                       "device_absences": st.resumed_gaps, "tared": st.tared, "pdc_tare_counts": st.tare_pdc,
                       "baseline_tracked_frames": st.tracked_frames, "bad_words_per_s": bad_rate.rate_hz,
                       "bad_words_total": st.counts.bad})
        if st.last_gap_s is not None:
            values["last_absence_s"] = round(st.last_gap_s, 3)
        values.update({f"bad_{k}": v for k, v in st.counts.as_dict().items()})
        f = self.stream.force_now(st)
        if f is not None:
            values["force_n"] = f
        last = self._last_frame.get(cs)
        age = None if last is None else time.monotonic() - last
        if self.scene_ended() and (age is None or age > self.stale_after_s):
            return Status("stale", "scene ended: the simulated scene was played to its end, no more frames", values)
        if age is None or age > self.stale_after_s:
            return Status("error", f"no frames {'yet' if age is None else f'for {age:.1f} s'} "
                                   f"(unplugged? wrong chip select?)", values)
        if bad_rate.rate_hz > 0:
            return Status("warn", f"{bad_rate.rate_hz:.1f} bad words/s (parity or error words)", values)
        if not serial and self.source is not None and cs in self.source.serial_errors:
            return Status("warn", f"serial number unreadable: {self.source.serial_errors[cs]}", values)
        return Status("ok", f"{fr:.0f} frames/s", values)


def main(args: Sequence[str] | None = None) -> int:
    """Entry point of the ``biotac_driver`` executable."""
    return run_node(BiotacDriver, args)


if __name__ == "__main__":
    raise SystemExit(main())
