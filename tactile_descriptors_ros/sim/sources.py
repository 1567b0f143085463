"""Simulated devices: the scene's samples as real wire bytes, made by the package's own encoders.

Each source is what :class:`~tactile_descriptors_ros.transports.simulated.SimulatedTransport`
expects (``read(max_bytes)``, ``recv(timeout_s)`` or ``transfer(cs, mosi)``),
so the real drivers decode simulated sensors exactly as they decode hardware:

* :class:`BiotacBridgeSource` -- the USB-serial bridge byte stream
  (:mod:`~tactile_descriptors_ros.codecs.bridge_serial`): one frame per frame
  period and BioTac, payload = the SPI reply words of the frame pattern
  (:func:`~tactile_descriptors_ros.codecs.biotac_spi.encode_words`);
* :func:`biotac_spi_bus` -- one :class:`~tactile_descriptors_ros.codecs.biotac_spi.BiotacSpiResponder`
  per chip select, answering sampling commands with the simulated values;
* :class:`SkinCanSource` -- :class:`can.Message` objects of the skin CAN layout
  (:mod:`~tactile_descriptors_ros.codecs.skin_can`);
* :class:`SkinSerialSource` -- the skin serial byte stream
  (:mod:`~tactile_descriptors_ros.codecs.skin_serial`).

Faults declared in the scene become wire faults: a dropped frame is not
sent but its sequence number is used up (the decoder sees a gap); a
``bad_parity`` word gets its high byte's parity bit flipped; a corrupt frame
gets a payload byte flipped after its CRC was computed (serial) or loses its
last data byte (CAN, whose own CRC would reject bit errors); an unplugged
cell sends nothing.

Sources simulate lazily, chunk by chunk (:func:`~.engine.iter_simulate`),
and by default hand out data as fast as it is read; with ``speed`` set they
pace it on the wall clock (``speed=1`` is real time).
"""

from __future__ import annotations

import heapq
import threading
import time
from collections import deque
from collections.abc import Collection, Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any

import numpy as np

from ..codecs.biotac_spi import IDLE, PDC, TAC, TDC, BiotacSpiResponder, FramePattern, channel_name, encode_words
from ..codecs.bridge_serial import BridgeFrame, BridgeFrameType, encode_bridge_frame
from ..errors import SceneError
from .engine import FAULT_CORRUPT, FAULT_PARITY, SimResult, iter_simulate
from .scene import Scene

__all__ = [
    "biotac_frame_words",
    "bridge_frames",
    "serial_number_frames",
    "skin_messages",
    "SkinRows",
    "BiotacBridgeSource",
    "SkinCanSource",
    "LoopedSkinCanSource",
    "SkinSerialSource",
    "biotac_spi_bus",
    "load_scene_for",
    "SKIN_STREAM_MODALITY",
    "wire_throughput",
]

#: Skin streams and their codec modality numbers (imported lazily with the codec).
SKIN_STREAM_MODALITY = {"accel": 1, "force": 2, "proximity": 3, "temperature": 4}


def load_scene_for(scene: str | Scene, robot_name: str) -> Scene:
    """Load a scene (name, path or :class:`Scene`) and check it was written for the robot ``robot_name``.

    Raises
    ------
    SceneError
        When the scene's robot is another one (a driver would decode the
        wrong cells), or the scene cannot be loaded.
    """
    from .scene import load_scene

    sc = scene if isinstance(scene, Scene) else load_scene(scene)
    if sc.robot.name != robot_name:
        raise SceneError(f"scene {sc.name!r} is for robot {sc.robot.name!r}, not {robot_name!r}",
                         key="scene.robot", source=sc.source)
    return sc


def _pattern_for(result: SimResult, pattern: FramePattern | str | None) -> FramePattern:
    pat = FramePattern.parse(pattern) if pattern is not None else FramePattern.default()
    ct = next(iter(result.cells.values()))
    pac, el = ct.streams["pac"], ct.streams["electrodes"]
    ppf = int(round(pac.rate_hz / el.rate_hz))
    if pat.pac_count != ppf or pat.electrode_count != el.counts.shape[0]:
        raise SceneError(f"frame pattern {pat} has {pat.pac_count} PAC and {pat.electrode_count} electrode words, "
                         f"the robot {ppf} and {el.counts.shape[0]}", key="pattern")
    return pat


def biotac_frame_words(cell: Any, pattern: FramePattern) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One BioTac's frames as SPI words in pattern order.

    Returns
    -------
    words : numpy.ndarray of int64, shape (n_frames, word_count)
    fault : numpy.ndarray of int8, same shape
    seq : numpy.ndarray of int64, shape (n_frames,)
        Frame numbers (gaps are dropped frames).
    t_ns : numpy.ndarray of int64, shape (n_frames,)
    """
    pdc = cell.streams["pdc"]
    n = pdc.seq.size
    ppf = pattern.pac_count
    words = np.zeros((n, pattern.word_count), dtype=np.int64)
    fault = np.zeros((n, pattern.word_count), dtype=np.int8)
    pac = cell.streams["pac"]
    words[:, pattern.pac_word_indices] = pac.counts[0].reshape(n, ppf)
    fault[:, pattern.pac_word_indices] = pac.fault[0].reshape(n, ppf)
    el = cell.streams["electrodes"]
    words[:, pattern.electrode_word_indices] = el.counts.T
    fault[:, pattern.electrode_word_indices] = el.fault.T
    for ch, name in ((PDC, "pdc"), (TAC, "tac"), (TDC, "tdc")):
        if ch in pattern.words:
            k = pattern.word_index(ch)
            words[:, k] = cell.streams[name].counts[0]
            fault[:, k] = cell.streams[name].fault[0]
    return words, fault, pdc.seq, pdc.t_ns


def _chip_select(cell: Any, k: int) -> int:
    return int(cell.extra.get("chip_select", k))


def serial_number_frames(result: SimResult, serial_prefix: str = "BTSIM",
                         chip_selects: Collection[int] | None = None) -> list[bytes]:
    """One bridge ``SERIAL_NUMBER`` frame per simulated BioTac (what a bridge sends when it starts).

    The serial number is ``serial_prefix`` and the cell id in 11 digits
    (16 ASCII characters at the most), as :func:`biotac_spi_bus` answers it.
    """
    out = []
    for k, cell in enumerate(result.cells.values()):
        cs = _chip_select(cell, k)
        if cell.kind != "biotac" or (chip_selects is not None and cs not in chip_selects):
            continue
        serial = f"{serial_prefix}{cell.cell_id:011d}"[:16].encode("ascii")
        out.append(encode_bridge_frame(BridgeFrame(BridgeFrameType.SERIAL_NUMBER, cs, 0, 0, serial)))
    return out


def bridge_frames(result: SimResult, pattern: FramePattern | str | None = None,
                  chip_selects: Collection[int] | None = None) -> list[tuple[int, bytes]]:
    """``(t_ns, frame bytes)`` of every BioTac frame of a simulation chunk, in time order.

    ``chip_selects``: only these BioTacs (default: all), as a bridge wired to
    some of the hand's fingertips.
    """
    pat = _pattern_for(result, pattern)
    out: list[tuple[int, int, bytes]] = []
    for k, cell in enumerate(result.cells.values()):
        cs = _chip_select(cell, k)
        if cell.kind != "biotac" or (chip_selects is not None and cs not in chip_selects):
            continue
        words, fault, seq, t_ns = biotac_frame_words(cell, pat)
        # a bridge sends a frame once its last word was sampled (the bridge clock stamps the frame's start)
        word_ns = 1e9 / (cell.streams["pdc"].rate_hz * pat.slot_count)
        done_ns = int(round((int(np.flatnonzero(np.asarray(pat.slots) != IDLE)[-1]) + 1) * word_ns))
        raw = np.frombuffer(encode_words(words.ravel()), dtype=np.uint8).reshape(len(seq), -1).copy()
        parity = np.nonzero(fault == FAULT_PARITY)
        raw[parity[0], 2 * parity[1]] ^= 0x01  # wrong odd-parity bit of the high byte
        corrupt = (fault == FAULT_CORRUPT).any(axis=1)
        start = result.scene.start_ns
        for i in range(len(seq)):
            frame = encode_bridge_frame(BridgeFrame(BridgeFrameType.SAMPLE, cs, int(seq[i]) & 0xFFFF,
                                                    int((int(t_ns[i]) - start) // 1000) & 0xFFFFFFFF,
                                                    raw[i].tobytes()))
            if corrupt[i]:
                b = bytearray(frame)
                b[12 + (int(seq[i]) * 7) % raw.shape[1]] ^= 0x5A  # garbled on the line: the CRC no longer matches
                frame = bytes(b)
            out.append((int(t_ns[i]) + done_ns, cs, frame))
    out.sort(key=lambda x: (x[0], x[1]))
    return [(t, f) for t, _, f in out]


class SkinRows:
    """Every skin sample of a chunk in time order, as arrays (built with array operations only).

    Rows are ordered by time stamp, then modality, then cell id.

    Attributes
    ----------
    t_ns, cell_id, modality, sequence : numpy.ndarray of int64, shape (n,)
    value_array : numpy.ndarray of int64, shape (n, 3)
        Counts (column 0 only for proximity and temperature, zeros beyond).
    corrupt : numpy.ndarray of bool, shape (n,)
    """

    def __init__(self, result: SimResult) -> None:
        streams = []
        for cell in result.cells.values():
            if cell.kind != "skin":
                continue
            for name, mod in SKIN_STREAM_MODALITY.items():
                st = cell.streams.get(name)
                if st is not None and st.seq.size:
                    streams.append((mod, cell.cell_id, st))
        if not streams:
            z = np.zeros(0, dtype=np.int64)
            self.t_ns, self.cell_id, self.modality, self.sequence = z, z.copy(), z.copy(), z.copy()
            self.value_array = np.zeros((0, 3), dtype=np.int64)
            self.corrupt = np.zeros(0, dtype=bool)
            return
        # Each stream is in time order: laid end to end by modality, then cell id, one stable sort by time puts
        # every row in time, modality, cell id order (a third of a three-key lexsort's time for a NAO chunk).
        streams.sort(key=lambda x: (x[0], x[1]))
        sizes = [st.seq.size for _, _, st in streams]
        t = np.concatenate([st.t_ns for _, _, st in streams]).astype(np.int64)
        order = np.argsort(t, kind="stable")
        self.t_ns = t[order]
        self.cell_id = np.repeat(np.array([c for _, c, _ in streams], dtype=np.int64), sizes)[order]
        self.modality = np.repeat(np.array([m for m, _, _ in streams], dtype=np.int64), sizes)[order]
        self.sequence = (np.concatenate([st.seq for _, _, st in streams]).astype(np.int64) & 0xFF)[order]
        self.corrupt = np.concatenate([(st.fault == FAULT_CORRUPT).any(axis=0) for _, _, st in streams])[order]
        vals = np.zeros((t.size, 3), dtype=np.int64)
        lo = 0
        for (_, _, st), n in zip(streams, sizes):
            vals[lo:lo + n, :st.counts.shape[0]] = st.counts.T
            lo += n
        self.value_array = vals[order]

    def __len__(self) -> int:
        return int(self.t_ns.size)

    def batch(self) -> Any:
        """All rows as a :class:`~tactile_descriptors_ros.codecs.skin.SkinSampleBatch` (stamps = sample times)."""
        from ..codecs.skin import SkinSampleBatch

        return SkinSampleBatch(self.cell_id, self.modality, self.sequence, self.value_array, self.t_ns)

    def values(self, i: int) -> tuple[int, ...]:
        """The counts of row ``i``."""
        k = 3 if self.modality[i] <= 2 else 1
        return tuple(self.value_array[i, :k].tolist())

    def sample(self, i: int) -> Any:
        """The :class:`~tactile_descriptors_ros.codecs.skin.SkinSample` of row ``i``."""
        from ..codecs.skin import Modality, SkinSample

        return SkinSample(int(self.cell_id[i]), Modality(int(self.modality[i])), int(self.sequence[i]),
                          self.values(i), int(self.t_ns[i]))


def skin_messages(result: SimResult) -> list[tuple[int, int, int, int, tuple[int, ...], bool]]:
    """Every skin sample of a chunk as ``(t_ns, cell_id, modality, sequence, values, corrupt)``, in time order."""
    rows = SkinRows(result)
    return [(int(rows.t_ns[i]), int(rows.cell_id[i]), int(rows.modality[i]), int(rows.sequence[i]), rows.values(i),
             bool(rows.corrupt[i])) for i in range(len(rows))]


class _Chunk:
    """Time-ordered items of one simulated chunk, made on demand.

    ``frames`` (a CAN frame array) or ``blob`` and ``offsets`` (a byte
    stream and its frame boundaries) hold the whole chunk's wire data for
    bulk reads.
    """

    def __init__(self, t_ns: np.ndarray, make: Any, frames: np.ndarray | None = None, blob: bytes | None = None,
                 offsets: np.ndarray | None = None) -> None:
        self.t_ns = t_ns
        self.make = make
        self.pos = 0
        self.frames = frames
        self.blob = blob
        self.offsets = offsets

    def due_end(self, due_ns: int | None) -> int:
        """Index after the last item due at ``due_ns`` (all when ``None``)."""
        if due_ns is None:
            return int(self.t_ns.size)
        return max(self.pos, int(np.searchsorted(self.t_ns, due_ns, side="right")))

    def __len__(self) -> int:
        return int(self.t_ns.size) - self.pos


#: Chunks of a paced scene simulated ahead of the one handed out (:meth:`_PacedSource._fill`).
AHEAD_CHUNKS = 2


class _PacedSource:
    """Items with time stamps from a lazily simulated scene, optionally paced on the wall clock."""

    def __init__(self, scene: Scene, speed: float | None = None, chunk_s: float = 10.0,
                 clock: Any = time.monotonic) -> None:
        if speed is not None and speed <= 0:
            raise SceneError(f"speed must be positive, got {speed}", key="speed")
        self.scene = scene
        self.speed = speed
        self.clock = clock
        self._chunks = iter_simulate(scene, max_chunk_s=chunk_s)
        self._items: deque[_Chunk] = deque()
        self._t0_wall: float | None = None
        self.exhausted = False
        self.results: list[dict[str, Any]] = []  # ground truth of the chunks simulated so far
        self._pool: ThreadPoolExecutor | None = None  # paced: simulates the next chunks ahead
        self._ahead: deque[Future] = deque()
        #: CPU time spent simulating chunks and putting them on the wire, on whichever thread [s]
        self.simulate_cpu_s = 0.0
        #: the native id of the thread that simulates a paced scene (``None``: not paced, or not started)
        self.thread_id: int | None = None

    def open(self) -> None:
        self._t0_wall = self.clock()

    def close(self) -> None:
        pass  # a chunk being simulated ahead stays: a transport opened again goes on with it

    def _convert(self, result: SimResult) -> _Chunk:
        raise NotImplementedError

    def _simulate_next(self) -> tuple[SimResult, _Chunk] | None:
        """The scene's next chunk, simulated and put on the wire (``None`` at its end)."""
        started = time.thread_time()
        try:
            try:
                result = next(self._chunks)
            except StopIteration:
                return None
            return result, self._convert(result)
        finally:
            self.simulate_cpu_s += time.thread_time() - started

    def _simulate_on_worker(self) -> tuple[SimResult, _Chunk] | None:
        """:meth:`_simulate_next` on the worker thread, which says who it is."""
        self.thread_id = threading.get_native_id()
        return self._simulate_next()

    def _fill(self) -> bool:
        """Queue the next chunk; False at the scene's end.

        Paced, the :data:`AHEAD_CHUNKS` chunks after it are simulated on a
        worker thread (one after the other) while this one is handed out:
        simulating a chunk of a large skin takes 0.1-0.2 s, which a reader
        waiting for it would see as a stalled bus (a backlog its driver sheds
        beyond its read cap).  One chunk ahead was not enough: the NAO soak
        scene has 2.4 s chunks followed by 9.4 s ones that take 1.6-1.9 s of
        CPU to simulate, more than 2.4 s of wall time for a driver sharing 2
        cores with its graph, and the driver waiting for it lost 0.17 % of its
        frames in 10 minutes.  The chunks and their order are the same either way.
        """
        if self.exhausted:
            return False
        if self.speed is not None and self._pool is None:
            # every chunk of a paced scene on the one worker thread, also the first, which is waited for here:
            # the simulator's CPU is then that thread's (a bench tells it from the driver's own by its id)
            self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="scene_ahead")
            self._ahead.append(self._pool.submit(self._simulate_on_worker))
        got = self._ahead.popleft().result() if self._ahead else self._simulate_next()
        if got is None:
            self.exhausted = True
            return False
        result, chunk = got
        self.results.append({"explorations": [e.to_dict() for e in result.explorations],
                             "faults": result.faults, "end_ns": result.end_ns})
        self._items.append(chunk)
        if self._pool is not None:
            while len(self._ahead) < AHEAD_CHUNKS:
                self._ahead.append(self._pool.submit(self._simulate_on_worker))
        return True

    @property
    def finished(self) -> bool:
        """The scene has ended: everything was simulated and handed out (a driver then reads nothing more)."""
        return self.exhausted and not any(len(c) for c in self._items) and not getattr(self, "_pending", b"")

    def _due_ns(self) -> int | None:
        if self.speed is None:
            return None
        if self._t0_wall is None:
            self._t0_wall = self.clock()
        return self.scene.start_ns + int((self.clock() - self._t0_wall) * self.speed * 1e9)

    def _head(self) -> _Chunk | None:
        while self._items and not len(self._items[0]):
            self._items.popleft()
        while not self._items:
            if not self._fill():
                return None
            while self._items and not len(self._items[0]):
                self._items.popleft()
        return self._items[0]

    def _pop_due(self) -> tuple[int, Any] | None:
        chunk = self._head()
        if chunk is None:
            return None
        i = chunk.pos
        due = self._due_ns()
        if due is not None and chunk.t_ns[i] > due:
            return None
        chunk.pos += 1
        return int(chunk.t_ns[i]), chunk.make(i)

    def __iter__(self) -> Iterator[tuple[int, Any]]:
        """All items in time order, ignoring pacing."""
        while True:
            chunk = self._head()
            if chunk is None:
                return
            i = chunk.pos
            chunk.pos += 1
            yield int(chunk.t_ns[i]), chunk.make(i)


class _ByteSource(_PacedSource):
    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._pending = bytearray()

    def read(self, max_bytes: int = 4096) -> bytes:
        """Up to ``max_bytes`` of the stream (what is due, when paced)."""
        while len(self._pending) < max_bytes:
            chunk = self._head()
            if chunk is not None and chunk.blob is not None:  # bulk: whole frames until max_bytes is reached
                end = chunk.due_end(self._due_ns())
                if end <= chunk.pos:
                    break
                off = chunk.offsets
                need = max_bytes - len(self._pending)
                stop = min(end, int(np.searchsorted(off, off[chunk.pos] + need, side="left")))
                stop = max(stop, chunk.pos + 1)
                self._pending += chunk.blob[off[chunk.pos]:off[stop]]
                chunk.pos = stop
                continue
            item = self._pop_due()
            if item is None:
                break
            self._pending += item[1]
        out = bytes(self._pending[:max_bytes])
        del self._pending[:max_bytes]
        return out


class BiotacBridgeSource(_ByteSource):
    """The USB-serial bridge of a simulated Shadow Hand: a byte stream for ``SimulatedTransport``.

    Parameters
    ----------
    scene : Scene
        A scene of a robot with BioTac cells.
    pattern : FramePattern or str, optional
        Frame pattern (default: the 44-word default frame).
    speed : float, optional
        Pace on the wall clock (1 = real time); default: as fast as read.
    chip_selects : collection of int, optional
        Only these BioTacs (default: every BioTac of the scene's robot).
    serial_prefix : str, optional
        When given, a ``SERIAL_NUMBER`` frame per BioTac comes first
        (:func:`serial_number_frames`), as a real bridge sends.
    """

    def __init__(self, scene: Scene, pattern: FramePattern | str | None = None, speed: float | None = None,
                 chunk_s: float = 10.0, clock: Any = time.monotonic, chip_selects: Collection[int] | None = None,
                 serial_prefix: str | None = None) -> None:
        super().__init__(scene, speed, chunk_s, clock)
        self.pattern = pattern
        self.chip_selects = None if chip_selects is None else frozenset(int(c) for c in chip_selects)
        self.serial_prefix = serial_prefix
        self._serials_sent = serial_prefix is None

    def _convert(self, result: SimResult) -> _Chunk:
        frames = bridge_frames(result, self.pattern, self.chip_selects)
        if not self._serials_sent:  # the bridge announces its BioTacs before the first sample
            t0 = result.scene.start_ns - 1
            frames = [(t0, f) for f in serial_number_frames(result, self.serial_prefix, self.chip_selects)] + frames
            self._serials_sent = True
        return _Chunk(np.array([t for t, _ in frames], dtype=np.int64), lambda i, _f=frames: _f[i][1])


class SkinSerialSource(_ByteSource):
    """Skin cells on the serial framing (:mod:`~tactile_descriptors_ros.codecs.skin_serial`).

    A chunk's frames are encoded at once (:func:`~tactile_descriptors_ros.codecs.skin_serial.encode_skin_frames`,
    byte for byte what :func:`~tactile_descriptors_ros.codecs.skin_serial.encode_skin_frame` makes);
    a corrupt frame's last payload byte is flipped after its CRC was computed.
    """

    def _convert(self, result: SimResult) -> _Chunk:
        from ..codecs.skin_serial import encode_skin_frames

        rows = SkinRows(result)
        blob, offsets = encode_skin_frames(rows.batch(), rows.corrupt)
        return _Chunk(rows.t_ns, lambda i: blob[offsets[i]:offsets[i + 1]], blob=blob, offsets=offsets)


class SkinCanSource(_PacedSource):
    """Skin cells on the CAN layout, for ``SimulatedTransport``.

    ``recv(timeout_s) -> can.Message | None`` hands out one python-can
    message at a time, as a CAN interface does; ``recv_batch(max_frames,
    timeout_s)`` hands out every due frame at once as a
    :data:`~tactile_descriptors_ros.codecs.can_frames.CAN_FRAME_DTYPE` array
    (the same frames, without a Python object per frame).  A chunk's frames
    are encoded at once (:func:`~tactile_descriptors_ros.codecs.skin_can.encode_can_frames`);
    a corrupt frame loses its last data byte.
    """

    def _convert(self, result: SimResult) -> _Chunk:
        from ..codecs.can_frames import messages_from_frames
        from ..codecs.skin_can import encode_can_frames

        rows = SkinRows(result)
        frames = encode_can_frames(rows.batch(), rows.corrupt)
        return _Chunk(rows.t_ns, lambda i: messages_from_frames(frames[i:i + 1])[0], frames=frames)

    def _wait(self, deadline: float | None) -> bool:
        """Sleep a little before trying again; False when the time is up or the scene is over."""
        if self._head() is None or deadline is None or time.monotonic() >= deadline:
            return False
        time.sleep(min(0.001, max(0.0, deadline - time.monotonic())))
        return True

    def recv(self, timeout_s: float | None = None) -> Any:
        """The next due message, or None (after waiting up to ``timeout_s`` when paced)."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while True:
            item = self._pop_due()
            if item is not None:
                return item[1]
            if not self._wait(deadline):
                return None

    def recv_batch(self, max_frames: int = 65536, timeout_s: float | None = None) -> np.ndarray:
        """Every due frame (at most ``max_frames``) as one frame array; waits up to ``timeout_s`` for the first."""
        from ..codecs.can_frames import empty_frames

        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        parts: list[np.ndarray] = []
        got = 0
        while got < max_frames:
            chunk = self._head()
            if chunk is None:
                break
            end = min(chunk.due_end(self._due_ns()), chunk.pos + max_frames - got)
            if end <= chunk.pos:
                if got or not self._wait(deadline):
                    break
                continue
            parts.append(chunk.frames[chunk.pos:end])
            got += end - chunk.pos
            chunk.pos = end
        if not parts:
            return empty_frames(0)
        return parts[0] if len(parts) == 1 else np.concatenate(parts)


class LoopedSkinCanSource(SkinCanSource):
    """A short scene's CAN frames played over and over, each lap re-stamped and re-numbered.

    The scene is simulated and encoded once, at :meth:`open`; every later
    lap hands out the same frames with their time stamps shifted by the
    scene's duration and every (cell, modality)'s sequence numbers advanced
    by its frames per lap, so the bus looks like one endless recording
    (continuous sample grids, no sequence gap).  A skin of thousands of cells
    then runs at full rate for as long as wanted at the cost of decoding it,
    not of simulating it (about 0.7 ms of CPU per cell and simulated second).

    Parameters
    ----------
    scene : Scene
        A scene without bus faults (dropped, corrupt frames, unplugged cells:
        a lap would repeat them) whose duration holds a whole number of
        periods of every stream, so the grids join across laps.
    speed, clock
        As :class:`SkinCanSource`.
    laps : int, optional
        Laps to play (default: endless).

    Raises
    ------
    SceneError
        For a scene with bus faults or a duration that breaks a stream's grid.
    """

    def __init__(self, scene: Scene, speed: float | None = None, chunk_s: float = 10.0,
                 clock: Any = time.monotonic, laps: int | None = None) -> None:
        super().__init__(scene, speed, chunk_s, clock)
        faults = sorted({"dropped_frames", "corrupt_frames", "unplug", "bad_parity"} & set(scene.effects))
        if faults:
            raise SceneError(f"a looped scene cannot declare bus faults ({', '.join(faults)}): every lap would "
                             "repeat them", key="effects", source=scene.source)
        if laps is not None and laps < 1:
            raise SceneError(f"laps must be at least 1, got {laps}", key="laps")
        self.laps = laps
        self.lap = 0
        self._lap_frames: np.ndarray | None = None
        self._lap_t_ns: np.ndarray | None = None
        self._lap_seq_step: np.ndarray | None = None
        self._lap_ns = 0

    def open(self) -> None:
        """Simulate and encode the scene once (the first lap), then start the clock."""
        if self._lap_frames is None:
            self._simulate_lap()
        super().open()

    def _simulate_lap(self) -> None:
        chunks = []
        while super()._fill():
            chunks.append(self._items.pop())
        frames = np.concatenate([c.frames for c in chunks]) if chunks else np.zeros(0)
        if not len(frames):
            raise SceneError("the scene has no skin cells to loop", key="scene.robot", source=self.scene.source)
        self._lap_ns = int(round(self.scene.duration_s * 1e9))
        rates = {r for ct in self.scene.robot.cell_types.values()
                 for r in (ct.vibration.rate_hz, ct.deformation.rate_hz)}
        for rate in rates:
            periods = self._lap_ns * rate / 1e9
            if abs(periods - round(periods)) > 1e-6:
                raise SceneError(f"the scene lasts {self.scene.duration_s} s, not a whole number of {rate:g} Hz "
                                 "periods: the sample grid would jump between laps", key="explorations",
                                 source=self.scene.source)
        _, inverse, counts = np.unique(frames["arbitration_id"], return_inverse=True, return_counts=True)
        self._lap_frames = frames
        self._lap_t_ns = np.concatenate([c.t_ns for c in chunks])
        self._lap_seq_step = counts[inverse].astype(np.int64)
        self.exhausted = False

    def _fill(self) -> bool:
        if self._lap_frames is None:
            self._simulate_lap()
        if self.laps is not None and self.lap >= self.laps:
            self.exhausted = True
            return False
        k = self.lap
        frames = self._lap_frames.copy()
        if k:
            frames["timestamp"] += k * self._lap_ns * 1e-9
            frames["data"][:, 0] = (frames["data"][:, 0] + k * self._lap_seq_step) & 0xFF
        from ..codecs.can_frames import messages_from_frames

        self._items.append(_Chunk(self._lap_t_ns + k * self._lap_ns,
                                  lambda i, _f=frames: messages_from_frames(_f[i:i + 1])[0], frames=frames))
        self.lap += 1
        return True


def biotac_spi_bus(result: SimResult, serial_prefix: str = "BTSIM") -> Any:
    """An :class:`~tactile_descriptors_ros.transports.simulated.SpiBus` of simulated BioTacs.

    Each chip select answers sampling commands with its next simulated value
    of the sampled channel (each channel has its own cursor, PAC advancing by
    one sample per command), so a driver polling the default frame pattern
    reads the simulated frames in order.  After the last sample a channel
    keeps returning its last value.  Bus faults (parity, drops) are not
    modelled at this level: use :class:`BiotacBridgeSource` for those.
    """
    from ..codecs.biotac_spi import PAC, electrode_channel
    from ..transports.simulated import SpiBus

    devices = {}
    for k, cell in enumerate(result.cells.values()):
        if cell.kind != "biotac":
            continue
        series: dict[int, np.ndarray] = {PAC: cell.streams["pac"].counts[0], PDC: cell.streams["pdc"].counts[0],
                                         TAC: cell.streams["tac"].counts[0], TDC: cell.streams["tdc"].counts[0]}
        for i, row in enumerate(cell.streams["electrodes"].counts):
            series[electrode_channel(i + 1)] = row
        cursors = dict.fromkeys(series, 0)

        def sample(channel: int, _s=series, _c=cursors) -> int:
            data = _s.get(channel)
            if data is None or not data.size:
                raise SceneError(f"channel {channel_name(channel)} is not simulated", key="pattern")
            i = min(_c[channel], data.size - 1)
            _c[channel] += 1
            return int(data[i])

        cs = _chip_select(cell, k)
        devices[cs] = BiotacSpiResponder(sample, serial_number=f"{serial_prefix}{cell.cell_id:011d}",
                                         electrode_count=cell.streams["electrodes"].counts.shape[0])
    return SpiBus(devices)


def merge_by_time(*streams: list[tuple[int, Any]]) -> list[tuple[int, Any]]:
    """Merge time-ordered ``(t_ns, item)`` lists."""
    return list(heapq.merge(*streams, key=lambda x: x[0]))


def wire_throughput(scene: Scene, wire: str = "can", reference_frames: int = 20000,
                    chunk_s: float = 2.0) -> dict[str, Any]:
    """Measure the skin wire path: simulate, encode, decode a scene's skin cells, batch and per frame.

    Plays the whole scene through the batch path (:class:`SkinCanSource` /
    :class:`SkinSerialSource` -> ``SimulatedTransport`` -> the decoder's
    batch method) and the first ``reference_frames`` frames through the
    per-frame path (one ``can.Message`` or frame at a time through
    :meth:`~tactile_descriptors_ros.codecs.skin_can.SkinCanDecoder.decode` /
    ``feed``), checking that both give the same samples.

    Returns
    -------
    dict
        ``frames``, ``simulated_s``, ``batch_wall_s``, ``batch_frames_per_s``,
        ``realtime_factor`` (simulated seconds per wall second, batch path),
        ``decode_wall_s`` (decoder share), ``reference_frames``,
        ``reference_frames_per_s`` (per-frame encode + decode), ``decoder_stats``.

    Raises
    ------
    SceneError
        Unknown wire.
    AssertionError
        Never expected: the batch and per-frame paths disagree.
    """
    from ..codecs.skin_can import SkinCanDecoder
    from ..codecs.skin_serial import SkinSerialDecoder
    from ..transports.simulated import SimulatedTransport

    if wire not in ("can", "serial"):
        raise SceneError(f"wire must be can or serial, got {wire!r}", key="wire")
    known = list(scene.robot.cell_index())
    src_cls = SkinCanSource if wire == "can" else SkinSerialSource
    new_dec = (lambda: SkinCanDecoder(known_cell_ids=known)) if wire == "can" else \
        (lambda: SkinSerialDecoder(known_cell_ids=known))
    tr = SimulatedTransport(src_cls(scene, chunk_s=chunk_s))
    tr.open()
    dec = new_dec()
    frames = 0
    decode_s = 0.0
    first_samples = None
    t0 = time.perf_counter()
    while True:
        if wire == "can":
            batch = tr.recv_batch(65536, 0.0)
            if not len(batch):
                break
            frames += len(batch)
            a = time.perf_counter()
            out = dec.decode_frames(batch)
        else:
            data = tr.read(1 << 20, 0.0)
            if not data:
                break
            a = time.perf_counter()
            out = dec.feed_batch(data)
            frames += len(out)
        decode_s += time.perf_counter() - a
        if first_samples is None:
            first_samples = out
    wall = time.perf_counter() - t0
    tr.close()
    # per-frame reference on the first frames
    ref_src = src_cls(scene, chunk_s=chunk_s)
    ref_src.open()
    ref = new_dec()
    got = []
    t1 = time.perf_counter()
    for k, (_, item) in enumerate(ref_src):
        if k >= reference_frames:
            break
        if wire == "can":
            s = ref.decode(item)
            if s is not None:
                got.append(s)
        else:
            got.extend(ref.feed(item))
    ref_wall = time.perf_counter() - t1
    n_ref = min(reference_frames, frames)
    if first_samples is not None:
        m = min(len(got), len(first_samples)) - 1  # the serial decoder may hold back the last frame
        assert first_samples.to_samples()[:m] == got[:m], "batch and per-frame decoders disagree"
    return {"wire": wire, "frames": frames, "simulated_s": round(scene.duration_s, 3),
            "batch_wall_s": round(wall, 3), "batch_frames_per_s": round(frames / wall) if wall else None,
            "realtime_factor": round(scene.duration_s / wall, 2) if wall else None,
            "decode_wall_s": round(decode_s, 3), "reference_frames": n_ref,
            "reference_frames_per_s": round(n_ref / ref_wall) if ref_wall else None,
            "decoder_stats": dec.stats.as_dict()}
