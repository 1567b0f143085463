"""Block averaging: a window described by the mean of the descriptors of its blocks.

A touch lasts what it lasts, and some quantities of a window depend on how
long it is (the Activity of a drifting electrode level grows with the
window, a spectrum's resolution with its length).  Block averaging cuts a
window into equal blocks of ``block_s`` seconds, at most ``block_hop_s``
apart, describes every block with the same feature engine
(:func:`~.aggregation.describe_window`: eq. 11-18, 28 and the feature groups
of :mod:`.features`) and averages the blocks' values.  Every value is then
an average of statistics of equal-length stretches, whose expectation does
not depend on the window's length, so a model trained on one touch length
holds on others.  Activity values are averaged as ``log1p`` and mapped back
by ``expm1`` (:func:`.scaling.log_activity`): the learners scale Activity by
``log1p``, so they see the mean log Activity.

A window no longer than one block is one block, described exactly as
:func:`~.aggregation.describe_window` describes it.

The split is by time on the slow (deformation) timeline: the frame period is
the median step of the cells' deformation stamps, a block is ``round(block_s
/ period)`` frames and the block starts (:func:`block_starts`) are spread
evenly from the window's first to its last possible start.  A block holds
the deformation samples and extra channels of its frames and the vibration
samples from its first frame up to the next frame (each frame's vibration
samples lie between its stamp and the next one's).  Force samples follow
the deformation samples when there are as many, else they are split in
proportion.

Per body part, the average runs over the blocks in which the part was in
contact (eq. 13 on the block); a part in contact in no block is zeros and
flagged ``NO_CONTACT``, as :func:`~.aggregation.describe_window` does.  The
quality flags of the blocks are OR-ed.

All blocks of a window are described by one call: the blocks' cells become
the cells of a robot whose body parts are the original ones once per block
(:func:`block_robot`, cached), so the kernel, the FFTs and the other groups
run once over every block's cells stacked instead of once per block.  Every
body part's values are computed from its own cells only, so the result is
the same, bit for bit, as describing each block on its own.
"""

from __future__ import annotations

import dataclasses
import threading
import weakref
from collections.abc import Mapping, Sequence

import numpy as np

from ..errors import ConfigError
from .aggregation import (
    BodyPartDescriptor,
    CellSignals,
    CellStacks,
    RobotDescriptor,
    describe_window,
    pool_body_parts,
    resolve_groups,
    robot_plan,
)
from .descriptors import Quality
from .robot import BodyPart, Cell, RobotDescription, check_blocks
from .scaling import activity_mask, log_activity

__all__ = ["block_starts", "block_mean", "split_cells", "block_robot", "describe_blocks"]


def block_starts(n_frames: int, block_frames: int, hop_frames: int) -> np.ndarray:
    """First frame of every block of a window of ``n_frames`` frames.

    A window no longer than a block is one block (start 0).  A longer one
    gets ``ceil((n - block) / hop) + 1`` blocks whose starts are spread
    evenly (rounded) from 0 to ``n - block``, so consecutive blocks are at
    most ``hop_frames`` apart and the first and last frames are covered.

    Raises
    ------
    ConfigError
        For a block shorter than 3 frames or a hop outside ``1..block_frames``.
    """
    if block_frames < 3 or not 1 <= hop_frames <= block_frames:
        raise ConfigError(f"blocks of {block_frames} frames every {hop_frames} frames: need a block of >= 3 "
                          "frames and a hop between 1 frame and the block", key="descriptor.block_s")
    if n_frames <= block_frames:
        return np.zeros(1, dtype=np.int64)
    n = int(np.ceil((n_frames - block_frames) / hop_frames)) + 1
    return np.round(np.linspace(0, n_frames - block_frames, n)).astype(np.int64)


def block_mean(values: np.ndarray, labels: Sequence[str]) -> np.ndarray:
    """Mean over the blocks (axis 0) of ``values``, Activity averaged as ``log1p`` then ``expm1``.

    Parameters
    ----------
    values : numpy.ndarray, shape (n_blocks, n_values)
    labels : sequence of str
        One per value; Activity is recognised by :func:`.scaling.activity_mask`.
    """
    values = np.asarray(values, dtype=np.float64)
    if values.shape[0] == 1:  # one block is the window's own descriptor, bit for bit
        return values[0].copy()
    mask = activity_mask(labels)
    mean = log_activity(values, mask).mean(axis=0)
    mean[mask] = np.expm1(mean[mask])
    return mean


def _frame_period_ns(cells: Mapping[int, CellSignals]) -> int | None:
    steps = [np.diff(np.asarray(c.deformation_t_ns, dtype=np.int64)) for c in cells.values()]
    steps = [s for s in steps if s.size]
    if not steps:
        return None
    period = int(np.median(np.concatenate(steps)))
    return period if period > 0 else None


def _cuts(sig: CellSignals, lo_ns: np.ndarray, hi_ns: np.ndarray) -> list[CellSignals]:
    """The samples of one cell in each block ``[lo_ns[k], hi_ns[k])`` of the slow timeline (views, no copies)."""
    t_v = np.asarray(sig.deformation_t_ns, dtype=np.int64)
    t_f = np.asarray(sig.vibration_t_ns, dtype=np.int64)
    n_blocks = lo_ns.size
    ab = np.searchsorted(t_v, np.concatenate([lo_ns, hi_ns]), side="left")
    f = np.full(ab.size, t_f.size, dtype=np.intp)
    inside = ab < t_v.size
    f[inside] = np.searchsorted(t_f, t_v[ab[inside]], side="left")
    force = np.asarray(sig.force_n)
    if force.shape[0] == t_v.size:
        fab = ab.tolist()
    else:  # force at its own rate: the same share of the window
        n = max(t_v.size, 1)
        fab = [int(round(x * force.shape[0] / n)) for x in ab.tolist()]
    vib, dfm = np.asarray(sig.vibration), np.asarray(sig.deformation)
    extra = None if sig.extra is None else np.asarray(sig.extra)
    ab_l, f_l = ab.tolist(), f.tolist()
    out = []
    for k in range(n_blocks):
        a, b, f_lo, f_hi = ab_l[k], ab_l[n_blocks + k], f_l[k], f_l[n_blocks + k]
        piece = object.__new__(CellSignals)  # every field of sig (flags, tare), the arrays cut below
        piece.__dict__.update(sig.__dict__)
        piece.vibration, piece.vibration_t_ns = vib[:, f_lo:f_hi], t_f[f_lo:f_hi]
        piece.deformation, piece.deformation_t_ns = dfm[:, a:b], t_v[a:b]
        piece.force_n = force[fab[k]:fab[n_blocks + k]]
        piece.extra = None if extra is None else extra[:, a:b]
        out.append(piece)
    return out


def split_cells(cells: Mapping[int, CellSignals], block_s: float, block_hop_s: float
                ) -> list[dict[int, CellSignals]]:
    """The blocks of a window's cell signals (see the module text); one block when the window is short.

    Raises
    ------
    ConfigError
        For a bad block setting (:func:`.robot.check_blocks`), or a block shorter than 3 frames.
    """
    block_s, block_hop_s = check_blocks(block_s, block_hop_s)
    if not block_s:  # before the frame period, which costs a difference per cell
        return [dict(cells)]
    period = _frame_period_ns(cells)
    if period is None:
        return [dict(cells)]
    t0 = min(int(c.deformation_t_ns[0]) for c in cells.values() if len(c.deformation_t_ns))
    t_last = max(int(c.deformation_t_ns[-1]) for c in cells.values() if len(c.deformation_t_ns))
    n_frames = int(round((t_last - t0) / period)) + 1
    block_frames = int(round(block_s * 1e9 / period))
    hop_frames = max(1, int(round(block_hop_s * 1e9 / period)))
    starts = block_starts(n_frames, block_frames, min(hop_frames, block_frames))
    if starts.size == 1:
        return [dict(cells)]
    half = period // 2  # frame k of the block owns the stamps within half a period of t0 + k * period
    lo = t0 + starts * period - half
    hi = t0 + (starts + block_frames) * period - half
    out: list[dict[int, CellSignals]] = [{} for _ in range(starts.size)]
    for cid, sig in cells.items():
        for block, piece in zip(out, _cuts(sig, lo, hi)):
            block[cid] = piece
    return out


def _mean_parts(grid: list[list[BodyPartDescriptor]]) -> tuple[BodyPartDescriptor, ...]:
    """:func:`_mean_part` of each body part (``grid[part][block]``); the parts in contact in every block and
    with the same labels are averaged together (the same sums: block after block, value by value)."""
    values: dict[int, np.ndarray] = {}
    together: dict[tuple[str, ...], list[int]] = {}
    for i, blocks in enumerate(grid):
        if len(blocks) > 1 and all(bp.contact for bp in blocks):
            together.setdefault(blocks[0].labels, []).append(i)
    for labels, idx in together.items():
        stacked = np.stack([[bp.values for bp in grid[i]] for i in idx], axis=1)  # (blocks, parts, values)
        mask = activity_mask(labels)
        mean = log_activity(stacked, mask).mean(axis=0)
        mean[:, mask] = np.expm1(mean[:, mask])
        values.update(zip(idx, mean))
    return tuple(_mean_part(blocks, values.get(i)) for i, blocks in enumerate(grid))


def _mean_part(blocks: list[BodyPartDescriptor], values: np.ndarray | None = None) -> BodyPartDescriptor:
    first = blocks[0]
    touching = [bp for bp in blocks if bp.contact]
    quality = 0
    for bp in blocks:
        quality |= int(bp.quality)
    if touching:
        if values is None:
            values = block_mean(np.stack([bp.values for bp in touching]), first.labels)
        quality &= ~int(Quality.NO_CONTACT)
    else:
        values = np.zeros(len(first.labels))
        quality |= int(Quality.NO_CONTACT)
    return BodyPartDescriptor(
        name=first.name, cell_type=first.cell_type, values=values, labels=first.labels, contact=bool(touching),
        cells_in_contact=max(bp.cells_in_contact for bp in blocks), cells_total=first.cells_total,
        mean_force_n=float(np.mean([bp.mean_force_n for bp in blocks])), quality=quality)


_BLOCK_ROBOTS: dict[tuple[int, int], tuple[weakref.ref, RobotDescription, int]] = {}
_BLOCK_ROBOTS_LOCK = threading.Lock()


def block_robot(robot: RobotDescription, n_blocks: int) -> tuple[RobotDescription, int]:
    """``robot`` with its body parts repeated ``n_blocks`` times, block after block (cached per robot object).

    Cell ``id`` of block ``b`` is cell ``id + b * stride`` of the returned
    robot; body parts keep their names and cell types.

    Returns
    -------
    (RobotDescription, int)
        The block robot and the id ``stride``.
    """
    key = (id(robot), int(n_blocks))
    hit = _BLOCK_ROBOTS.get(key)
    if hit is not None and hit[0]() is robot:
        return hit[1], hit[2]
    stride = max((c.id for p in robot.body_parts for c in p.cells), default=-1) + 1
    stride = max(stride, 1)
    parts = tuple(BodyPart(p.name, p.cell_type, tuple(Cell(c.id + b * stride, c.name, c.extra) for c in p.cells))
                  for b in range(n_blocks) for p in robot.body_parts)
    out = dataclasses.replace(robot, body_parts=parts)
    with _BLOCK_ROBOTS_LOCK:
        for k in [k for k, (ref, _, _) in _BLOCK_ROBOTS.items() if ref() is None]:
            del _BLOCK_ROBOTS[k]
        _BLOCK_ROBOTS[key] = (weakref.ref(robot), out, stride)
    return out, stride


def describe_blocks(robot: RobotDescription, cells: Mapping[int, CellSignals], *, block_s: float,
                    block_hop_s: float, layout: str | None = None, channels: str | None = None,
                    groups: tuple[str, ...] | None = None, force_threshold_n: float | None = None,
                    stacks: CellStacks | None = None) -> RobotDescriptor:
    """The robot's descriptor of one window as the mean over its blocks (block averaging).

    Parameters
    ----------
    robot, cells, layout, channels, groups, force_threshold_n
        As :func:`~.aggregation.describe_window`, which describes each block.
    block_s : float
        Block length in seconds; 0 describes the whole window at once.
    block_hop_s : float
        Largest step between consecutive blocks, ``0 < block_hop_s <= block_s``.
    stacks : CellStacks, optional
        The window's cells as rows of shared arrays (:class:`.windowing.Window`),
        for :func:`~.aggregation.describe_window` when the window is one block.

    Returns
    -------
    RobotDescriptor
        Per body part the :func:`block_mean` of its blocks in contact;
        ``extra["blocks"]`` is the number of blocks.

    Raises
    ------
    ConfigError
        For a bad block setting, and whatever :func:`~.aggregation.describe_window` raises.
    """
    pieces = split_cells(cells, block_s, block_hop_s)
    kw = {"channels": channels, "groups": groups, "force_threshold_n": force_threshold_n}
    if len(pieces) == 1:
        desc = describe_window(robot, pieces[0], layout=layout, stacks=stacks, **kw)
        desc.extra["blocks"] = 1
        return desc
    layout = layout or robot.descriptor.layout
    if layout not in ("concat", "pooled"):
        describe_window(robot, pieces[0], layout=layout, **kw)  # raises the layout error
    plan = robot_plan(robot)
    unknown = cells.keys() - plan.index.keys()
    if unknown:
        describe_window(robot, {cid: cells[cid] for cid in unknown}, layout=layout, **kw)  # raises naming them
    many, stride = block_robot(robot, len(pieces))
    joined = {cid + b * stride: sig for b, piece in enumerate(pieces) for cid, sig in piece.items()}
    desc = describe_window(many, joined, layout="concat", **kw)
    n_parts = len(robot.body_parts)
    parts = _mean_parts([[desc.body_parts[b * n_parts + i] for b in range(len(pieces))] for i in range(n_parts)])
    if layout == "pooled":
        values, labels = pool_body_parts(robot, parts)
    else:
        values = np.concatenate([bp.values for bp in parts])
        selection = resolve_groups(robot, channels, groups)
        labels = plan.concat_labels.get(selection)
        if labels is None:
            labels = plan.concat_labels[selection] = tuple(f"{bp.name}/{lab}" for bp in parts for lab in bp.labels)
    return RobotDescriptor(robot.name, layout, desc.channels, parts, values, labels, extra={"blocks": len(pieces)})
