"""Wire-byte sources that play a simulated scene to the drivers' ``simulated`` transport.

The simulator (:func:`tactile_descriptors_ros.sim.simulate`) renders a scene
into integer counts per cell and stream, with the faults it declares
(``Stream.fault``: parity, corrupt frames; gaps in ``Stream.seq``: dropped
frames).  These sources encode them with the package's own encoders, in
real time (``speed`` simulated seconds per wall second), so the drivers'
decoders see exactly what a bus would carry:

* :func:`biotac_bridge_source` -- our USB-serial bridge framing: one frame per
  BioTac and SPI frame, sequence numbers (a dropped frame is a gap), the
  simulated clock in ``t_us``, a parity fault as a flipped parity bit in the
  word, a corrupt frame as a byte flipped after the CRC was computed;
* :func:`skin_can_source` -- our skin CAN layout as ``can.Message`` objects,
  one per sample, with the per-(cell, modality) sequence numbers and the
  simulated time in ``timestamp``.

The sources start their clock when the transport is opened.
"""

from __future__ import annotations

import heapq
import time
from collections.abc import Mapping

import numpy as np

from ..codecs.biotac_spi import CHANNELS, FramePattern, encode_words
from ..codecs.bridge_serial import BridgeFrame, BridgeFrameType, encode_bridge_frame
from ..core.robot import RobotDescription
from ..errors import SceneError

__all__ = ["BiotacBridgeSource", "biotac_bridge_source", "SkinCanSource", "skin_can_source", "simulate_scene"]


def simulate_scene(scene_path: str, robot: RobotDescription):
    """Load and render a scene, checking it was written for ``robot``."""
    from ..sim import load_scene, simulate

    scene = load_scene(scene_path)
    if scene.robot.name != robot.name:
        raise SceneError(f"scene {scene.name!r} is for robot {scene.robot.name!r}, not {robot.name!r}",
                         key="scene.robot", source=scene.source)
    return simulate(scene)


class _Clock:
    def __init__(self, start_ns: int, speed: float) -> None:
        self.start_ns = int(start_ns)
        self.speed = float(speed)
        self.t0: float | None = None

    def open(self) -> None:
        self.t0 = time.monotonic()

    def now_ns(self) -> int:
        if self.t0 is None:
            return self.start_ns - 1
        return self.start_ns + int((time.monotonic() - self.t0) * self.speed * 1e9)


class BiotacBridgeSource:
    """A byte source emitting bridge frames of simulated BioTacs as their time comes.

    Parameters
    ----------
    result : SimResult
    pattern : FramePattern
        Must have as many PAC samples per frame as the simulation (PAC rate / frame rate).
    chip_selects : mapping of int to str
        Chip select -> sensor (cell) name.
    speed : float
        Simulated seconds per wall-clock second.
    """

    def __init__(self, result, pattern: FramePattern, chip_selects: Mapping[int, str], speed: float = 1.0) -> None:
        self.result = result
        self.clock = _Clock(result.scene.start_ns, speed)
        by_name = {c.name: c for c in result.cells.values()}
        frames: list[tuple[int, int, bytes]] = []
        for cs, name in chip_selects.items():
            cell = by_name.get(name)
            if cell is None:
                raise SceneError(f"the scene simulates no BioTac named {name!r}")
            serial = f"BTSIM{cell.cell_id:011d}"[:16]
            frames.append((result.scene.start_ns - 1, cs, encode_bridge_frame(
                BridgeFrame(BridgeFrameType.SERIAL_NUMBER, cs, 0, 0, serial.encode("ascii")))))
            frames += self._cell_frames(cell, cs, pattern)
        frames.sort(key=lambda f: (f[0], f[1]))
        self.t_ns = np.array([f[0] for f in frames], np.int64)
        self.chunks = [f[2] for f in frames]
        self.next = 0
        self.pending = bytearray()
        self.end_ns = result.end_ns

    @staticmethod
    def _cell_frames(cell, cs: int, pattern: FramePattern) -> list[tuple[int, int, bytes]]:
        st = cell.streams
        el, pac = st["electrodes"], st["pac"]
        ppf = pattern.pac_count
        if int(round(pac.rate_hz / el.rate_hz)) != ppf:
            raise SceneError(f"the frame pattern has {ppf} PAC samples per frame; the simulation has "
                             f"{pac.rate_hz / el.rate_hz:g}")
        frames_idx = el.seq
        pos = np.searchsorted(pac.seq, frames_idx * ppf)
        ok = pos + ppf <= pac.seq.size
        pac_idx = np.clip(pos[:, None] + np.arange(ppf)[None, :], 0, max(pac.seq.size - 1, 0))
        ok &= np.all(pac.seq[pac_idx] == frames_idx[:, None] * ppf + np.arange(ppf)[None, :], axis=1)
        n = frames_idx.size
        words = np.zeros((n, pattern.word_count), np.int64)
        fault = np.zeros((n, pattern.word_count), np.int8)
        pac_slots = pattern.pac_word_indices
        words[:, pac_slots] = pac.counts[0][pac_idx]
        fault[:, pac_slots] = pac.fault[0][pac_idx]
        for w, ch in enumerate(pattern.words):
            if ch == CHANNELS["PAC"]:
                continue
            name = {CHANNELS["PDC"]: "pdc", CHANNELS["TAC"]: "tac", CHANNELS["TDC"]: "tdc"}.get(ch)
            if name is not None:
                words[:, w] = st[name].counts[0]
                fault[:, w] = st[name].fault[0]
            else:
                e = ch - CHANNELS["E1"]
                words[:, w] = el.counts[e]
                fault[:, w] = el.fault[e]
        out = []
        for i in np.flatnonzero(ok):
            payload = bytearray(encode_words(np.clip(words[i], 0, 4095)))
            for w in np.flatnonzero(fault[i] == 1):
                payload[2 * w + 1] ^= 0x01  # wrong parity bit in the low byte
            wire = bytearray(encode_bridge_frame(BridgeFrame(BridgeFrameType.SAMPLE, cs, int(frames_idx[i]) & 0xFFFF,
                                                             (int(el.t_ns[i]) // 1000) & 0xFFFFFFFF, bytes(payload))))
            if np.any(fault[i] == 2):
                wire[12] ^= 0xFF  # corrupt after the CRC was computed
            out.append((int(el.t_ns[i]), cs, bytes(wire)))
        return out

    def open(self) -> None:
        self.clock.open()

    def close(self) -> None:
        self.clock.t0 = None

    @property
    def finished(self) -> bool:
        """True once every frame has been sent."""
        return self.next >= len(self.chunks) and not self.pending

    def read(self, max_bytes: int) -> bytes:
        now = self.clock.now_ns()
        j = int(np.searchsorted(self.t_ns, now, side="right"))
        if j > self.next:
            self.pending += b"".join(self.chunks[self.next:j])
            self.next = j
        out = bytes(self.pending[:max_bytes])
        del self.pending[:max_bytes]
        return out


def biotac_bridge_source(scene_path: str, robot: RobotDescription, pattern: FramePattern, word_rate_hz: float,
                         chip_selects: Mapping[int, str], speed: float = 1.0) -> BiotacBridgeSource:
    """Render ``scene_path`` and return its bridge byte source (see :class:`BiotacBridgeSource`)."""
    result = simulate_scene(scene_path, robot)
    rate = pattern.rates(word_rate_hz)
    cell = next(iter(result.cells.values()))
    sim_frame_hz = cell.streams["electrodes"].rate_hz
    if abs(rate.frame_rate_hz - sim_frame_hz) > 1e-6 * sim_frame_hz:
        raise SceneError(f"the frame pattern at {word_rate_hz} words/s gives {rate.frame_rate_hz:.3f} frames/s; "
                         f"the scene simulates {sim_frame_hz} frames/s (robot description rates)")
    return BiotacBridgeSource(result, pattern, chip_selects, speed)


class SkinCanSource:
    """A CAN source (``recv(timeout_s)``) emitting simulated skin-cell frames as their time comes.

    Messages are generated per time slice (not all at start: a NAO scene
    holds millions of samples).
    """

    _MODALITIES = (("accel", 1), ("force", 2), ("proximity", 3), ("temperature", 4))

    def __init__(self, result, cell_ids: Mapping[int, str] | None = None, speed: float = 1.0,
                 slice_ns: int = 20_000_000) -> None:
        self.result = result
        self.clock = _Clock(result.scene.start_ns, speed)
        self.cells = [c for c in result.cells.values() if cell_ids is None or c.cell_id in cell_ids]
        self.slice_ns = int(slice_ns)
        self.cursor = {(c.cell_id, s): 0 for c in self.cells for s, _ in self._MODALITIES if s in c.streams}
        self.generated_to_ns = result.scene.start_ns - 1
        self.heap: list = []
        self.counter = 0
        self.end_ns = result.end_ns

    def open(self) -> None:
        self.clock.open()

    def close(self) -> None:
        self.clock.t0 = None

    @property
    def finished(self) -> bool:
        return self.generated_to_ns >= self.end_ns and not self.heap

    def _generate(self, until_ns: int) -> None:
        import can

        from ..codecs.skin_can import arbitration_id

        while self.generated_to_ns < until_ns and self.generated_to_ns < self.end_ns:
            hi = self.generated_to_ns + self.slice_ns
            for c in self.cells:
                for sname, mod in self._MODALITIES:
                    s = c.streams.get(sname)
                    if s is None:
                        continue
                    k0 = self.cursor[(c.cell_id, sname)]
                    k1 = int(np.searchsorted(s.t_ns, hi, side="right"))
                    if k1 <= k0:
                        continue
                    self.cursor[(c.cell_id, sname)] = k1
                    arb = arbitration_id(c.cell_id, mod)
                    for k in range(k0, k1):
                        if np.any(s.fault[:, k] == 2):
                            continue  # a corrupt CAN frame never passes the controller's CRC: lost
                        vals = s.counts[:, k]
                        data = bytes([int(s.seq[k]) & 0xFF]) + _pack(mod, vals)
                        msg = can.Message(arbitration_id=arb, is_extended_id=True, data=data,
                                          timestamp=int(s.t_ns[k]) * 1e-9)
                        self.counter += 1
                        heapq.heappush(self.heap, (int(s.t_ns[k]), self.counter, msg))
            self.generated_to_ns = hi

    def recv(self, timeout_s: float | None = None):
        deadline = time.monotonic() + (timeout_s or 0.0)
        while True:
            now = self.clock.now_ns()
            if not self.heap or self.heap[0][0] > now:
                self._generate(now + self.slice_ns)
            if self.heap and self.heap[0][0] <= now:
                return heapq.heappop(self.heap)[2]
            if time.monotonic() >= deadline:
                return None
            time.sleep(0.001)

    def send(self, msg) -> None:
        """The simulated cells ignore commands."""


def _pack(modality: int, vals: np.ndarray) -> bytes:
    from ..codecs.skin import Modality, pack_values

    m = Modality(modality)
    if m is Modality.ACCEL:
        vals = np.clip(vals, -512, 511)
    elif m is Modality.FORCE:
        vals = np.clip(vals, 0, 4095)
    elif m is Modality.PROXIMITY:
        vals = np.clip(vals, 0, 0xFFFE)
    return pack_values(m, tuple(int(v) for v in vals))


def skin_can_source(scene_path: str, robot: RobotDescription, cell_ids: Mapping[int, str] | None = None,
                    speed: float = 1.0) -> SkinCanSource:
    """Render ``scene_path`` and return its CAN source (see :class:`SkinCanSource`)."""
    return SkinCanSource(simulate_scene(scene_path, robot), cell_ids, speed)
