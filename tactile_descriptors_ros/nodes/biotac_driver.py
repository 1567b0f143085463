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

``~/tare`` (std_srvs/Trigger) zeroes the PDC and electrode baselines over the
last ``tare.window_s`` of frames; it is refused while any BioTac reads a force
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
from collections import Counter, deque
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from rclpy.lifecycle import TransitionCallbackReturn

from ..codecs.biotac_spi import MAX_SENSORS, BiotacFrameDecoder, BiotacFrames, FramePattern, WordCounts
from ..codecs.bridge_serial import BridgeDecoder, BridgeFrameType
from ..errors import CodecError, ConfigError
from .common import RateMeter, Status, declare, run_node
from .conversions import BioTacBatch, biotac_batch_to_msg
from .driver_base import DriverBase
from .qos import QosDefaults, declare_qos
from .window_node import FRAMES_TOPIC

__all__ = ["BiotacDriver", "SensorConfig", "SpiFrameSource", "BridgeFrameSource", "Unwrapper", "main"]

TRANSPORTS = ("cheetah", "serial", "simulated", "loopback")


@dataclass
class SensorConfig:
    """One BioTac as the robot description places it."""

    chip_select: int
    sensor_name: str
    body_part: str
    frame_id: str


class Unwrapper:
    """Unwrap a wrapping counter (16-bit sequence, 32-bit microseconds) to a growing integer."""

    def __init__(self, modulus: int) -> None:
        self.modulus = int(modulus)
        self.last: int | None = None
        self.value = 0

    def __call__(self, raw: int) -> int:
        raw = int(raw) % self.modulus
        if self.last is None:
            self.value = raw
        else:
            d = (raw - self.last) % self.modulus
            if d >= self.modulus // 2:
                d -= self.modulus
            self.value += d
        self.last = raw
        return self.value


@dataclass
class ReadItem:
    """Frames of one BioTac from one read: decoded frames, their device times [ns] and sequence numbers."""

    chip_select: int
    frames: BiotacFrames
    device_t_ns: np.ndarray
    sequence: np.ndarray


class SpiFrameSource:
    """SPI sampling (Cheetah, or a simulated SPI bus): one frame of every BioTac per :meth:`read`.

    The device clock is the frame count times the frame period; reads are
    paced to ``word_rate_hz`` (a real adapter paces itself; pacing then only
    sleeps when ahead of schedule).
    """

    def __init__(self, spi, pattern: FramePattern, chip_selects: Sequence[int], word_rate_hz: float,
                 decoder: BiotacFrameDecoder) -> None:
        from ..transports.biotac import read_frame, read_serial_number

        self._read_frame = read_frame
        self._read_serial = read_serial_number
        self.spi = spi
        self.pattern = pattern
        self.chip_selects = list(chip_selects)
        self.word_rate_hz = float(word_rate_hz)
        self.period_ns = int(round(pattern.slot_count / self.word_rate_hz * 1e9))
        self.decoder = decoder
        self.frame = 0
        self._t0: float | None = None
        self.overruns = 0
        self.serial_numbers: dict[int, str] = {}
        self.serial_errors: dict[int, str] = {}

    def read_serial_numbers(self) -> None:
        for cs in self.chip_selects:
            try:
                self.serial_numbers[cs] = self._read_serial(self.spi, cs)
            except CodecError as exc:
                self.serial_errors[cs] = str(exc)

    def read(self) -> list[ReadItem]:
        now = time.monotonic()
        if self._t0 is None:
            self._t0 = now
        due = self._t0 + self.frame * self.period_ns * 1e-9
        if due > now:
            time.sleep(due - now)
        elif now - due > 0.5:  # fell behind by more than half a second: restart the schedule
            self.overruns += 1
            self._t0 = now - self.frame * self.period_ns * 1e-9
        replies = self._read_frame(self.spi, self.pattern, self.chip_selects, self.word_rate_hz)
        k = self.frame
        self.frame += 1
        out = []
        for cs in self.chip_selects:
            frames = self.decoder.decode_many(cs, replies[cs], first_sequence=k)
            out.append(ReadItem(cs, frames, np.array([k * self.period_ns], np.int64), np.array([k], np.int64)))
        return out


class BridgeFrameSource:
    """Our USB-serial bridge framing over a byte transport (serial, loopback, simulated)."""

    def __init__(self, stream, pattern: FramePattern, chip_selects: Sequence[int],
                 decoder: BiotacFrameDecoder, read_timeout_s: float = 0.05) -> None:
        self.stream = stream
        self.pattern = pattern
        self.chip_selects = set(int(c) for c in chip_selects)
        self.decoder = decoder
        self.bridge = BridgeDecoder()
        self.read_timeout_s = float(read_timeout_s)
        self.serial_numbers: dict[int, str] = {}
        self.serial_errors: dict[int, str] = {}
        self.unconfigured_frames: Counter[int] = Counter()
        self.decode_errors = 0
        self._seq = {cs: Unwrapper(1 << 16) for cs in self.chip_selects}
        self._t = {cs: Unwrapper(1 << 32) for cs in self.chip_selects}

    def read_serial_numbers(self) -> None:
        """Serial numbers arrive as bridge frames; nothing to ask."""

    def read(self) -> list[ReadItem]:
        data = self.stream.read(65536, self.read_timeout_s)
        if not data:
            return []
        out: list[ReadItem] = []
        for fr in self.bridge.feed(data):
            cs = fr.chip_select
            if cs not in self.chip_selects:
                self.unconfigured_frames[cs] += 1
                continue
            if fr.kind == BridgeFrameType.SERIAL_NUMBER:
                try:
                    self.serial_numbers[cs] = fr.payload.decode("ascii")
                except UnicodeDecodeError:
                    self.serial_errors[cs] = f"serial number is not ASCII: {fr.payload!r}"
                continue
            seq = self._seq[cs](fr.sequence)
            t_us = self._t[cs](fr.t_us)
            try:
                frames = self.decoder.decode_many(cs, fr.payload, first_sequence=seq)
            except CodecError:
                self.decode_errors += 1
                continue
            out.append(ReadItem(cs, frames, np.array([t_us * 1000], np.int64), np.array([seq], np.int64)))
        return out


@dataclass
class _SensorState:
    cfg: SensorConfig
    frames: list[tuple[int, int, BiotacFrames]] = field(default_factory=list)  # (seq, stamp_ns, frames)
    recent_pdc: deque = field(default_factory=lambda: deque(maxlen=2000))  # (stamp_ns, pdc)
    recent_el: deque = field(default_factory=lambda: deque(maxlen=2000))  # (stamp_ns, electrodes)
    tare_pdc: float = 0.0
    tare_electrodes: np.ndarray | None = None
    tared: bool = False
    tracked_frames: int = 0
    counts: WordCounts = field(default_factory=WordCounts)
    frames_total: int = 0
    messages: int = 0
    lost_frames: int = 0
    next_seq: int | None = None
    last_frame_monotonic: float | None = None
    rate: RateMeter = field(default_factory=RateMeter)
    bad_rate: RateMeter = field(default_factory=RateMeter)
    first_stamp_ns: int | None = None


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
        full, self.robot = self._declare_robot("biotac", "shadow_hand", "BioTac")
        self.transport_name = declare(self, "transport", "cheetah", "device transport", choices=TRANSPORTS)
        self.pattern = FramePattern.parse(declare(self, "frame_pattern", "default",
                                                  "frame pattern: default | paper_50hz | biotac_sp | channel list"))
        self.word_rate_hz = declare(self, "word_rate_hz", 4400.0, "SPI word slots per second", minimum=1.0)
        self.batch_frames = declare(self, "batch_frames", 10, "frames per message", minimum=1)
        self.wire = declare(self, "wire", "auto", "framing on the transport: spi (SPI sampling), bridge (our "
                            "serial framing); auto = spi for cheetah, bridge otherwise", choices=("auto", "spi", "bridge"))
        self._declare_stamps_and_tare(full.contact.force_threshold_n, "baseline from the first frames [s] (0 = off)",
                                      "frames averaged by ~/tare [s]")
        self.track_s = declare(self, "tare.track_s", 0.5, "PDC baseline follows drift with this time constant while "
                               "the force is below tare.track_band_n [s] (0 = tare only at start and on ~/tare)",
                               minimum=0.0)
        self.track_band_n = declare(self, "tare.track_band_n", self.contact_threshold_n,
                                    "baseline tracking only while |force| is below this [N]", minimum=0.0)
        # weight of one frame in the tracked baseline (exponential, time constant tare.track_s)
        frame_hz = self.pattern.rates(self.word_rate_hz).frame_rate_hz
        self._track_alpha = min(1.0, 1.0 / (frame_hz * self.track_s)) if self.track_s > 0 else 0.0
        self.pdc_pa_per_count = declare(self, "pdc_pa_per_count", 0.0,
                                        "static pressure scale [Pa/count] (0 = not calibrated)", minimum=0.0)
        self.topic_fmt = declare(self, "frames_topic", FRAMES_TOPIC, "frames topic of a body part ({body_part})")
        self.tp = {
            "cheetah": {"port": declare(self, "cheetah.port", -1, "Cheetah port (-1 = first free)"),
                        "bitrate_khz": declare(self, "cheetah.bitrate_khz", 4400, "SPI clock [kHz]", minimum=1)},
            "serial": {"port": declare(self, "serial.port", "/dev/ttyACM0", "bridge serial port or pyserial URL"),
                       "baudrate": declare(self, "serial.baudrate", 921600, "baud rate", minimum=1)},
        }
        self.sim_scene = declare(self, "sim.scene", "", "scene played by the simulated transport")
        self.sim_speed = declare(self, "sim.speed", 1.0, "simulated time per wall time", minimum=1e-3)
        autostart = declare(self, "autostart", True, "configure and activate at start")
        self.qos_frames = declare_qos(self, "frames", QosDefaults("reliable", "volatile", 50))

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
        self.state: dict[int, _SensorState] = {}
        self.publishers_by_cs: dict[int, object] = {}
        self._offset_ns: int | None = None
        self._start(autostart, [("transport", self._transport_status)]
                    + [(cfg.sensor_name, lambda cs=cs: self._sensor_status(cs))
                       for cs, cfg in sorted(self.sensors.items())])

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
            self.source = BridgeFrameSource(self.transport, self.pattern, sorted(self.sensors), decoder)
        self.source.read_serial_numbers()
        for cs, err in self.source.serial_errors.items():
            self.get_logger().warning(f"{self.sensors[cs].sensor_name} (chip select {cs}): no serial number: {err}")

    def _configured(self) -> TransitionCallbackReturn:
        self.state = {cs: _SensorState(cfg) for cs, cfg in self.sensors.items()}
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
        for item in items:
            self._handle(item)

    def _stamp(self, device_t_ns: int) -> int:
        if self.stamp_source == "device":
            return int(device_t_ns)
        now = self.get_clock().now().nanoseconds
        if self._offset_ns is None:
            self._offset_ns = now - int(device_t_ns)
        stamp = self._offset_ns + int(device_t_ns)
        if self.resync_s > 0 and abs(stamp - now) > self.resync_s * 1e9:
            self.faults["clock_resync"] += 1
            self._offset_ns = now - int(device_t_ns)
            stamp = now
        return stamp

    def _handle(self, item: ReadItem) -> None:
        st = self.state[item.chip_select]
        frames = item.frames
        stamp = self._stamp(int(item.device_t_ns[0]))
        seq = int(item.sequence[0])
        with self._lock:
            st.frames_total += len(frames)
            st.counts = st.counts + frames.counts
            st.rate.add(len(frames))
            if frames.counts.bad:
                st.bad_rate.add(frames.counts.bad)
            st.last_frame_monotonic = time.monotonic()
            if st.next_seq is not None and seq != st.next_seq:
                if seq > st.next_seq:
                    st.lost_frames += seq - st.next_seq
                self._flush(st)
            st.next_seq = seq + len(frames)
            if st.first_stamp_ns is None:
                st.first_stamp_ns = stamp
            for k in range(len(frames)):
                if frames.pdc_valid[k]:
                    st.recent_pdc.append((stamp, float(frames.pdc[k])))
                    if st.tared and self._track_alpha > 0:
                        self._track_baseline(st, float(frames.pdc[k]))
                if frames.electrodes_valid[k].all():
                    st.recent_el.append((stamp, frames.electrodes[k].astype(np.float64)))
            if not st.tared and self.tare_on_start_s > 0:
                if stamp - st.first_stamp_ns >= self.tare_on_start_s * 1e9:
                    ok, why = self._tare_one(st, self.tare_on_start_s, check_contact=False)
                    if ok:
                        self.get_logger().info(f"{st.cfg.sensor_name}: start tare {why}")
                    else:
                        self.get_logger().warning(f"{st.cfg.sensor_name}: start tare failed: {why}",
                                               throttle_duration_sec=5.0)
                return  # nothing is published before the start tare
            st.frames.append((seq, stamp, frames))
            if sum(len(f) for _, _, f in st.frames) >= self.batch_frames:
                self._flush(st)

    def _flush(self, st: _SensorState) -> None:
        if not st.frames:
            return
        pac_off = self.pattern.pac_offsets_ns(self.word_rate_hz)
        seq0, t0, _ = st.frames[0]
        frame_t = np.array([t for _, t, f in st.frames for _ in range(len(f))], np.int64)
        stamp = int(frame_t[0] + pac_off[0])
        pac = np.concatenate([f.pac for _, _, f in st.frames]).reshape(-1)
        pac_t = (frame_t[:, None] + pac_off[None, :]).reshape(-1)
        el = np.concatenate([f.electrodes for _, _, f in st.frames])
        bad = sum(f.counts.bad for _, _, f in st.frames)
        batch = BioTacBatch(
            stamp_ns=stamp, pac=pac, pac_offset_ns=pac_t - stamp, frame_offset_ns=frame_t - stamp,
            pdc=np.concatenate([f.pdc for _, _, f in st.frames]), tac=np.concatenate([f.tac for _, _, f in st.frames]),
            tdc=np.concatenate([f.tdc for _, _, f in st.frames]), electrodes=el, first_frame_sequence=seq0,
            bad_words=bad)
        st.frames = []
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
    def _track_baseline(self, st: _SensorState, pdc: float) -> None:
        """Follow slow PDC drift (temperature) while the finger is clearly not touching.

        A start tare alone lets the baseline drift by tenths of a newton
        within a minute, above the release threshold, so explorations never
        end.  Frames whose tared force is under ``tare.track_band_n`` move the
        baseline towards them; a touch (force above the band) freezes it.
        """
        if abs(pdc - st.tare_pdc) * self.force_n_per_count < self.track_band_n:
            st.tare_pdc += (pdc - st.tare_pdc) * self._track_alpha
            st.tracked_frames += 1

    def _force_now(self, st: _SensorState) -> float | None:
        if not st.tared or not st.recent_pdc:
            return None
        last = [p for _, p in list(st.recent_pdc)[-10:]]
        return (float(np.mean(last)) - st.tare_pdc) * self.force_n_per_count

    def _tare_one(self, st: _SensorState, window_s: float, check_contact: bool) -> tuple[bool, str]:
        if check_contact:
            f = self._force_now(st)
            if f is not None and f >= self.contact_threshold_n:
                return False, f"{st.cfg.sensor_name} is in contact ({f:.2f} N >= {self.contact_threshold_n} N)"
        if not st.recent_pdc:
            return False, f"{st.cfg.sensor_name}: no valid PDC samples yet"
        newest = st.recent_pdc[-1][0]
        pdc = [p for t, p in st.recent_pdc if t >= newest - window_s * 1e9]
        el = [e for t, e in st.recent_el if t >= newest - window_s * 1e9]
        if len(pdc) < 3:
            return False, f"{st.cfg.sensor_name}: only {len(pdc)} valid PDC samples in the last {window_s} s"
        st.tare_pdc = float(np.mean(pdc))
        st.tare_electrodes = np.mean(el, axis=0) if el else None
        st.tared = True
        return True, f"PDC baseline {st.tare_pdc:.1f} counts from {len(pdc)} frames"

    def _srv_tare(self, request, response):
        with self._lock:
            if not self.state or all(not s.recent_pdc for s in self.state.values()):
                response.success, response.message = False, "no frames received yet (is the driver active?)"
                return response
            touching = []
            for st in self.state.values():
                f = self._force_now(st)
                if f is not None and f >= self.contact_threshold_n:
                    touching.append(f"{st.cfg.sensor_name} ({f:.2f} N)")
            if touching:
                response.success = False
                response.message = (f"refused: in contact: {', '.join(touching)}; release the fingers "
                                    f"(force < {self.contact_threshold_n} N) and call ~/tare again")
                return response
            results = [self._tare_one(st, self.tare_window_s, check_contact=False) for st in self.state.values()]
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
        fr = st.rate.rate_hz
        values.update({"frame_rate_hz": fr, "pac_rate_hz": fr * self.pattern.pac_count,
                       "expected_frame_rate_hz": rates.frame_rate_hz, "frames": st.frames_total,
                       "messages": st.messages, "lost_frames": st.lost_frames, "tared": st.tared,
                       "pdc_tare_counts": st.tare_pdc,
                       "baseline_tracked_frames": st.tracked_frames, "bad_words_per_s": st.bad_rate.rate_hz,
                       "bad_words_total": st.counts.bad})
        values.update({f"bad_{k}": v for k, v in st.counts.as_dict().items()})
        f = self._force_now(st)
        if f is not None:
            values["force_n"] = f
        age = None if st.last_frame_monotonic is None else time.monotonic() - st.last_frame_monotonic
        if age is None or age > 1.0:
            return Status("error", f"no frames {'yet' if age is None else f'for {age:.1f} s'} "
                                   f"(unplugged? wrong chip select?)", values)
        if st.bad_rate.rate_hz > 0:
            return Status("warn", f"{st.bad_rate.rate_hz:.1f} bad words/s (parity or error words)", values)
        if not serial and self.source is not None and cs in self.source.serial_errors:
            return Status("warn", f"serial number unreadable: {self.source.serial_errors[cs]}", values)
        return Status("ok", f"{fr:.0f} frames/s", values)


def main(args: Sequence[str] | None = None) -> int:
    """Entry point of the ``biotac_driver`` executable."""
    return run_node(BiotacDriver, args)


if __name__ == "__main__":
    raise SystemExit(main())
