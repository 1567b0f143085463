"""One body part's skin cells per message: per-cell batches <-> flat per-part arrays, without ROS.

The skin driver publishes the samples of all cells of a body part over one
batch as one ``SkinPartFrames`` message (``msg/msg/SkinPartFrames.msg``)
instead of one ``SkinCellFrame`` per cell: rclpy and DDS cost about 0.2 ms
of CPU per message whatever its size, so 116 cells at 50 ms batches were
2,320 messages/s, and 7 body parts at 10 ms batches are 700.

This module holds everything about that layout that needs no ROS:

* :class:`SkinPartFrames` -- the message's arrays, checked: a list of *runs*
  (one cell's samples of one batch) whose samples are concatenated in run
  order, with per-run sample counts;
* :func:`pack_skin_part` -- the driver side: per-cell
  :class:`~..nodes.conversions.SkinFrame` s -> one :class:`SkinPartFrames`;
* :meth:`SkinPartFrames.frames` -- the exact inverse (the reference);
* :func:`skin_part_chunk` -- the window node side: one
  :class:`SkinPartFrames` -> one :class:`~..core.windowing.PartChunk`, the
  per-sample work (validity, tared mean force, extra channels) done once
  over the whole body part with array operations (:func:`skin_part_chunks`:
  the same as a :class:`~..core.windowing.CellChunk` per run);
* :class:`PartGatherer` -- collects the cells' batches of a body part until
  every cell that is sending has one, so a part goes out as one message per
  batch even when its cells' batches complete in different reads.

The ROS message <-> :class:`SkinPartFrames` copies are in
:mod:`..nodes.conversions` (``skin_part_to_msg`` / ``skin_part_from_msg``).
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np

from ..core.windowing import CellChunk, PartChunk
from ..errors import SignalError
from ..markers import INVALID_ACCEL, INVALID_COUNT
from .frames import SkinFrame

__all__ = ["SkinPartFrames", "SkinRun", "pack_skin_part", "skin_part_chunks", "skin_part_chunk", "PartGatherer",
           "SKIN_PART_EXTRA_CHANNELS", "extra_rows", "RunCheck", "RunChecker"]

#: Extra channels (robot description ``extra_channels``) a ``SkinPartFrames`` carries.
SKIN_PART_EXTRA_CHANNELS: tuple[str, ...] = ("proximity", "temperature")


@dataclass
class SkinRun:
    """One cell's batch on its way into a part message: the cell, its samples and its force tare."""

    cell_id: int
    frame: SkinFrame
    tare_counts: np.ndarray  # (3,) float64, copied when the batch was cut


@dataclass
class SkinPartFrames:
    """The arrays of one ``SkinPartFrames`` message (see ``msg/msg/SkinPartFrames.msg``).

    Attributes
    ----------
    stamp_ns : int
        ``header.stamp``: every offset is relative to it.
    body_part : str
    cell_ids, sequence, bad_frames : numpy.ndarray of int64, shape (n_runs,)
    accel_count, force_count : numpy.ndarray of int64, shape (n_runs,)
        Samples of each run in the flat arrays below (in run order).
    temperature_c : numpy.ndarray of float64, shape (n_runs,)
    force_tare_counts : numpy.ndarray of float64, shape (n_runs, 3)
    accel : numpy.ndarray of int16, shape (3, sum(accel_count))
        x, y, z; ``INVALID_ACCEL`` where unreadable.
    accel_offset_ns : numpy.ndarray of int64, shape (sum(accel_count),)
    force : numpy.ndarray of uint16, shape (3, sum(force_count))
        ``INVALID_COUNT`` where unreadable.
    force_offset_ns : numpy.ndarray of int64, shape (sum(force_count),)
    proximity : numpy.ndarray of uint16, shape (sum(force_count),) or (0,)
    accel_mps2_per_count, force_n_per_count, proximity_per_count : float
    frame_id : str
        ``header.frame_id``.

    Raises
    ------
    SignalError
        On construction, for arrays whose lengths disagree with the counts.
    """

    stamp_ns: int
    body_part: str
    cell_ids: np.ndarray
    sequence: np.ndarray
    accel_count: np.ndarray
    force_count: np.ndarray
    temperature_c: np.ndarray
    force_tare_counts: np.ndarray
    bad_frames: np.ndarray
    accel: np.ndarray
    accel_offset_ns: np.ndarray
    force: np.ndarray
    force_offset_ns: np.ndarray
    proximity: np.ndarray = field(default_factory=lambda: np.zeros(0, np.uint16))
    accel_mps2_per_count: float = 0.0
    force_n_per_count: float = 0.0
    proximity_per_count: float = 0.0
    frame_id: str = ""

    def __post_init__(self) -> None:
        n = len(self.cell_ids)
        for name in ("sequence", "accel_count", "force_count", "temperature_c", "bad_frames"):
            if len(getattr(self, name)) != n:
                raise SignalError(f"{len(getattr(self, name))} {name} values for {n} cell runs")
        if np.size(self.force_tare_counts) != 3 * n:
            raise SignalError(f"force_tare_counts must hold 3 values per cell run ({3 * n}), "
                              f"got {np.size(self.force_tare_counts)}")
        if n and (np.min(self.accel_count) < 0 or np.min(self.force_count) < 0):
            raise SignalError("negative sample counts")
        n_a, n_f = int(np.sum(self.accel_count)), int(np.sum(self.force_count))
        if np.ndim(self.accel) != 2 or np.shape(self.accel) != (3, n_a):
            raise SignalError(f"accel must be (3, {n_a}) for the runs' accelerometer counts, "
                              f"got {np.shape(self.accel)}")
        if len(self.accel_offset_ns) != n_a:
            raise SignalError(f"{len(self.accel_offset_ns)} accelerometer offsets for {n_a} samples")
        if np.ndim(self.force) != 2 or np.shape(self.force) != (3, n_f):
            raise SignalError(f"force must be (3, {n_f}) for the runs' force counts, got {np.shape(self.force)}")
        if len(self.force_offset_ns) != n_f:
            raise SignalError(f"{len(self.force_offset_ns)} force offsets for {n_f} samples")
        if len(self.proximity) not in (0, n_f):
            raise SignalError(f"{len(self.proximity)} proximity samples for {n_f} force samples")

    def __len__(self) -> int:
        return len(self.cell_ids)

    def frames(self) -> list[tuple[int, SkinFrame, np.ndarray]]:
        """Per run: (cell id, its :class:`SkinFrame`, its force tare [counts]); the inverse of :func:`pack_skin_part`.

        A run's proximity is empty when every one of its samples is
        ``INVALID_COUNT`` (a cell that sent none), as its ``SkinCellFrame``
        would have been.
        """
        out = []
        a_end = np.cumsum(self.accel_count)
        f_end = np.cumsum(self.force_count)
        tare = np.asarray(self.force_tare_counts, dtype=np.float64).reshape(-1, 3)
        for i in range(len(self)):
            a0, a1 = int(a_end[i] - self.accel_count[i]), int(a_end[i])
            f0, f1 = int(f_end[i] - self.force_count[i]), int(f_end[i])
            t0 = self.stamp_ns + (int(self.accel_offset_ns[a0]) if a1 > a0 else 0)
            prox = np.asarray(self.proximity[f0:f1], dtype=np.uint16) if len(self.proximity) else np.zeros(0, np.uint16)
            if prox.size and (prox == INVALID_COUNT).all():
                prox = np.zeros(0, np.uint16)
            frame = SkinFrame(
                stamp_ns=t0,
                accel=np.asarray(self.accel[:, a0:a1], dtype=np.int16).copy(),
                accel_offset_ns=np.asarray(self.accel_offset_ns[a0:a1], dtype=np.int64) + (self.stamp_ns - t0),
                force=np.asarray(self.force[:, f0:f1], dtype=np.uint16).copy(),
                force_offset_ns=np.asarray(self.force_offset_ns[f0:f1], dtype=np.int64) + (self.stamp_ns - t0),
                proximity=prox.copy(),
                temperature_c=float(self.temperature_c[i]),
                sequence=int(self.sequence[i]),
                bad_frames=int(self.bad_frames[i]))
            out.append((int(self.cell_ids[i]), frame, tare[i].copy()))
        return out


def pack_skin_part(body_part: str, runs: Sequence[SkinRun], *, accel_mps2_per_count: float = 0.0,
                   force_n_per_count: float = 0.0, proximity_per_count: float = 0.0,
                   frame_id: str | None = None) -> SkinPartFrames:
    """Per-cell batches of one body part -> one :class:`SkinPartFrames` (the skin driver's message).

    ``header.stamp`` is the earliest first accelerometer sample of the runs
    (the earliest force sample for runs without accelerometer samples);
    ``frame_id`` defaults to the body part.  Proximity is one value per force
    sample, ``INVALID_COUNT`` for the runs that carry none, or empty when no
    run has any.

    Raises
    ------
    SignalError
        For no runs, or a run whose arrays are inconsistent.
    """
    if not runs:
        raise SignalError(f"no cell batches to pack for body part {body_part!r}")
    frames = [r.frame for r in runs]
    starts = [f.stamp_ns + int(f.accel_offset_ns[0]) if len(f.accel_offset_ns) else
              (f.stamp_ns + int(f.force_offset_ns[0]) if len(f.force_offset_ns) else f.stamp_ns) for f in frames]
    t0 = min(starts)
    n_a = np.fromiter((len(f.accel_offset_ns) for f in frames), np.int64, len(frames))
    n_f = np.fromiter((len(f.force_offset_ns) for f in frames), np.int64, len(frames))
    accel = np.concatenate([np.asarray(f.accel, dtype=np.int16).reshape(3, -1) for f in frames], axis=1)
    force = np.concatenate([np.asarray(f.force, dtype=np.uint16).reshape(3, -1) for f in frames], axis=1)
    off_a = np.concatenate([np.asarray(f.accel_offset_ns, np.int64) + (f.stamp_ns - t0) for f in frames])
    off_f = np.concatenate([np.asarray(f.force_offset_ns, np.int64) + (f.stamp_ns - t0) for f in frames])
    if any(len(f.proximity) for f in frames):
        proximity = np.concatenate([np.asarray(f.proximity, np.uint16) if len(f.proximity) else
                                    np.full(len(f.force_offset_ns), INVALID_COUNT, np.uint16) for f in frames])
    else:
        proximity = np.zeros(0, np.uint16)
    return SkinPartFrames(
        stamp_ns=int(t0), body_part=body_part,
        cell_ids=np.array([r.cell_id for r in runs], dtype=np.int64),
        sequence=np.array([f.sequence for f in frames], dtype=np.int64),
        accel_count=n_a, force_count=n_f,
        temperature_c=np.array([f.temperature_c for f in frames], dtype=np.float64),
        force_tare_counts=np.concatenate([np.asarray(r.tare_counts, np.float64).reshape(3) for r in runs]).reshape(-1, 3),
        bad_frames=np.array([f.bad_frames for f in frames], dtype=np.int64),
        accel=accel, accel_offset_ns=off_a, force=force, force_offset_ns=off_f, proximity=proximity,
        accel_mps2_per_count=float(accel_mps2_per_count), force_n_per_count=float(force_n_per_count),
        proximity_per_count=float(proximity_per_count), frame_id=body_part if frame_id is None else frame_id)


def skin_part_chunks(part: SkinPartFrames, extra_channels: Sequence[str] = ()) -> list[tuple[int, CellChunk]]:
    """One :class:`CellChunk` per run, in run order: :meth:`~..core.windowing.PartChunk.chunks` of
    :func:`skin_part_chunk` (slices of the part's arrays).

    Raises
    ------
    SignalError
        For an extra channel this message does not carry.
    """
    return skin_part_chunk(part, extra_channels).chunks()


def extra_rows(proximity: np.ndarray, temperature_c: np.ndarray, force_count: np.ndarray, n_force: int,
               extra_channels: Sequence[str]) -> np.ndarray | None:
    """The extra channels of a body part's message, one row each over its ``n_force`` force samples
    (:func:`skin_part_chunk`); None when none are asked for."""
    if not extra_channels:
        return None
    prox = np.asarray(proximity)
    cols = {"proximity": (np.where(prox != INVALID_COUNT, prox.astype(np.float64), np.nan) if prox.size
                          else np.full(n_force, np.nan)),
            "temperature": np.repeat(np.asarray(temperature_c, dtype=np.float64), force_count)}
    return np.stack([cols[c] for c in extra_channels])


def skin_part_chunk(part: SkinPartFrames, extra_channels: Sequence[str] = ()) -> PartChunk:
    """The whole message as one :class:`~..core.windowing.PartChunk` (vibration accelerometer, deformation force).

    Per sample exactly what ``skin_msg_to_chunk`` made of a ``SkinCellFrame``:
    force (contact gate, eq. 27) is the mean of the three tared force sensors
    times ``force_n_per_count``, NaN where any of them is ``INVALID_COUNT``;
    ``extra_channels`` (names of :data:`SKIN_PART_EXTRA_CHANNELS`) become the
    chunk's extra rows, one value per force sample: ``proximity`` in counts
    (NaN where ``INVALID_COUNT`` or absent), ``temperature`` the run's
    ``temperature_c``.  Each run's force tare becomes its deformation tare.
    The per-sample work is done once over the whole body part, with no
    Python loop over runs.

    Raises
    ------
    SignalError
        For an extra channel this message does not carry.
    """
    unknown = [c for c in extra_channels if c not in SKIN_PART_EXTRA_CHANNELS]
    if unknown:
        raise SignalError(f"SkinPartFrames carries no extra channel {unknown[0]!r}")
    n = len(part)
    ax, ay, az = part.accel[0], part.accel[1], part.accel[2]
    m_total = int(part.force.shape[1])
    acc = np.empty((3, ax.shape[0]), dtype=np.int32)
    acc[0], acc[1], acc[2] = ax, ay, az
    vib_ok = (ax != INVALID_ACCEL) & (ay != INVALID_ACCEL) & (az != INVALID_ACCEL)
    f3 = part.force
    forces = f3.astype(np.int32)
    f_ok = (f3 != INVALID_COUNT).all(axis=0)
    tare = np.asarray(part.force_tare_counts, dtype=np.float64).reshape(n, 3)
    f_count = np.asarray(part.force_count, dtype=np.int64)
    a_count = np.asarray(part.accel_count, dtype=np.int64)
    tare_s = np.repeat(tare, f_count, axis=0).T  # (3, m_total): each sample's own cell tare
    mean_n = (forces - tare_s).mean(axis=0) * float(part.force_n_per_count)
    force_n = np.where(f_ok, mean_n, np.nan)
    t_a = np.asarray(part.accel_offset_ns, dtype=np.int64) + int(part.stamp_ns)
    t_f = np.asarray(part.force_offset_ns, dtype=np.int64) + int(part.stamp_ns)
    extra = extra_rows(part.proximity, part.temperature_c, f_count, m_total, extra_channels)
    return PartChunk(cell_ids=np.asarray(part.cell_ids, dtype=np.int64), vibration_count=a_count,
                     deformation_count=f_count, vibration=acc, vibration_t_ns=t_a, deformation=forces,
                     deformation_t_ns=t_f, force_n=force_n, vibration_valid=vib_ok, deformation_valid=f_ok,
                     extra=extra, deformation_tare=tare)


@dataclass(frozen=True)
class RunCheck:
    """What :meth:`RunChecker.check` found in one message's runs."""

    #: per run, whether it is of a served cell of the message's body part (the runs to keep)
    mine: np.ndarray
    #: runs of cells that no served body part has, and the first such cell id
    unknown: int
    first_unknown: int | None
    #: runs of served cells sent on another body part's message, and the first such cell id
    other_part: int
    first_other_part: int | None
    #: the kept runs' cell batches that never arrived (gaps in each cell's batch numbers)
    lost: int
    #: the kept runs whose batch number is at or before the cell's newest: a driver that started again
    restarts: int
    #: the kept runs' ``bad_frames``
    bad_frames: int


class RunChecker:
    """A body part's message's runs against the served cells and each cell's batch numbers (32-bit, wrapping).

    The window node's check of every ``SkinPartFrames``: runs of unknown cells or of
    another body part's cells are left out and counted; each kept run's batch number
    follows its cell's newest (the numbers between are lost batches, a number at or
    before it a restart of the driver's count, as ``SequenceTracker.track_run`` with
    one number).  Runs are taken in order, so a cell with two runs in one message is
    checked twice.  With the compiled backend one pass does it all
    (:func:`.numba_kernel.check_runs`; about 40 us of array operations a NAO message
    before); the numpy path gives the same results.

    Parameters
    ----------
    parts : mapping of body part -> cell ids
        The served cells of each body part (a cell id on one body part only).
    """

    def __init__(self, parts: dict[str, Iterable[int]]) -> None:
        served = sorted((int(c), k) for k, cells in enumerate(parts.values()) for c in cells)
        self.part_code = {name: k for k, name in enumerate(parts)}
        self.ids = np.array([c for c, _ in served], np.int64)
        self.part = np.array([k for _, k in served], np.int64)
        self.high = np.zeros(len(served), np.int64)  # each cell's newest batch number, unwrapped
        self.have = np.zeros(len(served), bool)
        self._out = np.zeros(7, np.int64)

    def check(self, part: str, ids: np.ndarray, sequence: np.ndarray, bad_frames: np.ndarray) -> RunCheck:
        """Check one message's runs (cell ids, batch numbers, bad frames, one each per run) of body part ``part``."""
        from ..core import fast, windowing

        code = self.part_code.get(part, -1)
        kernel = fast.kernel_module() if windowing.COMPILED_INTAKE else None
        if kernel is not None and ids.dtype == np.int64 and sequence.dtype == bad_frames.dtype == np.uint32 \
                and fast.loaded_layout(ids, sequence, bad_frames) \
                and ids.size == sequence.size == bad_frames.size:
            mine = np.empty(ids.size, bool)
            out = self._out
            kernel.check_runs(ids, sequence, bad_frames, self.ids, self.part, code, self.have, self.high, mine, out)
            n_unknown, first_unknown, n_other, first_other, lost, restarts, bad = out.tolist()
            return RunCheck(mine, n_unknown, first_unknown if n_unknown else None, n_other,
                            first_other if n_other else None, lost, restarts, bad)
        return self._check_numpy(code, np.asarray(ids, np.int64), sequence, bad_frames)

    def _check_numpy(self, code: int, ids: np.ndarray, sequence: np.ndarray, bad_frames: np.ndarray) -> RunCheck:
        if not self.ids.size:
            return RunCheck(np.zeros(ids.size, bool), int(ids.size), int(ids[0]) if ids.size else None, 0, None,
                            0, 0, 0)
        pos = np.minimum(np.searchsorted(self.ids, ids), self.ids.size - 1)
        known = self.ids[pos] == ids
        mine = known & (self.part[pos] == code)
        other = known & ~mine
        n_unknown, n_other = int((~known).sum()), int(other.sum())
        first_unknown = int(ids[~known][0]) if n_unknown else None
        first_other = int(ids[other][0]) if n_other else None
        if not mine.any():
            return RunCheck(mine, n_unknown, first_unknown, n_other, first_other, 0, 0, 0)
        lost, restarts = self._sequence(pos[mine], np.asarray(sequence)[mine])
        return RunCheck(mine, n_unknown, first_unknown, n_other, first_other, lost, restarts,
                        int(np.asarray(bad_frames)[mine].sum()))

    def _sequence(self, cells: np.ndarray, seq: np.ndarray) -> tuple[int, int]:
        """Lost batches and restarts of the runs of ``cells`` (positions) with batch numbers ``seq``."""
        if np.unique(cells).size < cells.size:  # a cell twice in one message: one run after the other
            lost = restarts = 0
            for c, q in zip(cells.tolist(), seq.tolist()):
                got = self._sequence(np.array([c]), np.array([q], np.int64))
                lost, restarts = lost + got[0], restarts + got[1]
            return lost, restarts
        seq = seq.astype(np.int64)
        have = self.have[cells]
        d = (seq - (self.high[cells] + 1)) % (1 << 32)
        back = have & (d >= 1 << 31)
        lost = np.where(have & ~back, d, 0)
        self.high[cells] = np.where(have & ~back, self.high[cells] + 1 + d, seq)
        self.have[cells] = True
        return int(lost.sum()), int(back.sum())


class PartGatherer:
    """Collects cells' batches per body part until the part's message is due.

    A body part's batches go out together when every cell *expected* on it
    has one pending: at first every configured cell of the part, later the
    cells of its previous message (a cell that fell silent is not waited for
    again), plus any cell that shows up.  A part is also due when one of its
    cells has a second batch pending (another cell is late or silent: it is
    not waited for longer than a batch), and, by :meth:`flush_stale`, when its
    oldest pending batch has waited ``max_wait_s`` of host time (the last
    batches before a bus goes quiet).

    Parameters
    ----------
    parts : mapping of body part -> cell ids
        The served cells of each body part.
    max_wait_s : float
        Host time after which :meth:`flush_stale` sends a part's pending batches.
    now_s : callable() -> float, optional
        Host clock (``time.monotonic``).
    """

    def __init__(self, parts: dict[str, Iterable[int]], max_wait_s: float,
                 now_s=time.monotonic) -> None:
        self.max_wait_s = float(max_wait_s)
        self._now = now_s
        self._expected: dict[str, set[int]] = {p: set(cells) for p, cells in parts.items()}
        self._pending: dict[str, list[SkinRun]] = {p: [] for p in parts}
        self._since: dict[str, float] = {}
        #: parts sent because a cell was late or silent (a part message without every expected cell)
        self.partial = 0

    def add(self, body_part: str, run: SkinRun) -> None:
        """Queue one cell's batch (call :meth:`due` after a read's batches are queued)."""
        pending = self._pending[body_part]
        if not pending:
            self._since[body_part] = self._now()
        pending.append(run)

    def due(self) -> list[tuple[str, list[SkinRun]]]:
        """The parts whose message is due, with their runs (in the order they were queued); removed here."""
        out = []
        for part, pending in self._pending.items():
            if not pending:
                continue
            ids = [r.cell_id for r in pending]
            present = set(ids)
            if self._expected[part] <= present:
                out.append((part, self._take(part, present)))
            elif len(present) < len(ids):  # a cell has a second batch: the missing ones are late or silent
                self.partial += 1
                out.append((part, self._take(part, present)))
        return out

    def flush_stale(self) -> list[tuple[str, list[SkinRun]]]:
        """Parts whose oldest pending batch has waited ``max_wait_s``; removed here."""
        now = self._now()
        out = []
        for part, pending in self._pending.items():
            if pending and now - self._since[part] >= self.max_wait_s:
                present = {r.cell_id for r in pending}
                if not self._expected[part] <= present:
                    self.partial += 1
                out.append((part, self._take(part, present)))
        return out

    def _take(self, part: str, present: set[int]) -> list[SkinRun]:
        runs = self._pending[part]
        self._pending[part] = []
        self._expected[part] = present
        # a cell's runs stay in time order; cells in the order their first run came
        runs.sort(key=lambda r: r.frame.stamp_ns)
        return runs

    def pending(self) -> int:
        """Batches waiting."""
        return sum(len(p) for p in self._pending.values())
