"""The skin driver's read path in one process: CPU per read with compiled decoding against numpy's.

``tactile bench --read-cost`` plays the scale graph's looped scene
(:func:`~tactile_descriptors_ros.sim.synthetic.scale_robot_files`: N cells of
the NAO's skin cell sliding over cork) as CAN frames and runs what the skin
driver's reader thread runs on every read, without ROS: the simulated bus
hands out the frames due in ``read_period_s`` of scene time
(:class:`~tactile_descriptors_ros.sim.sources.LoopedSkinCanSource` on a
stepped clock), :meth:`~tactile_descriptors_ros.codecs.skin_can.SkinCanDecoder.decode_frames`
decodes them, :meth:`~tactile_descriptors_ros.streams.skin.SkinStream.add_parts`
stamps and cuts them into body part messages and
:func:`~tactile_descriptors_ros.nodes.conversions.skin_part_to_msg` builds each
message (publishing is left out: that is the middleware's).

Two paths over the same reads, alternating, in one run: the compiled
decoding and sequence tracking (:data:`~tactile_descriptors_ros.codecs.skin_can.COMPILED_DECODE`,
:data:`~tactile_descriptors_ros.codecs.sequence.COMPILED_TRACKING`) and
numpy's.  Before anything is timed both must give the same messages, field
by field (floats bit for bit), and the same counters (the run stops otherwise).  Reported: CPU
time of the thread per read and per cell and second of data, the minimum
over ``repeat`` runs of each path (this machine is shared), and their ratio.
"""

from __future__ import annotations

import tempfile
import time
from collections import Counter
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np

__all__ = ["read_cost", "format_read_cost"]


def _reads(n_cells: int, read_period_s: float | None, batch_s: float | None, seconds: float, out_dir: str,
           parts: int = 1) -> tuple[list[np.ndarray], object, float, float]:
    """The frame arrays the driver would read, a read period of scene time each (the first second left out: the
    grids settle), the scene's robot (``parts`` body parts on one bus), and the driver's read period and batch
    (the NAO graph's unless given)."""
    import yaml

    from tactile_descriptors_ros.sim.scene import load_scene
    from tactile_descriptors_ros.sim.sources import LoopedSkinCanSource
    from tactile_descriptors_ros.sim.synthetic import scale_robot_files

    path = scale_robot_files(n_cells, parts, out_dir, batch_s=batch_s, read_period_s=read_period_s, one_driver=True)
    with open(path, encoding="utf-8") as fh:
        driver = next(n for n in yaml.safe_load(fh)["nodes"].values() if n["executable"] == "skin_driver")
    params = driver["parameters"]
    period, batch = float(params.get("read_period_s") or 0.0), float(params["batch_s"])
    if not period > 0:
        raise RuntimeError("--read-cost needs a positive read period (reading as soon as frames are due has no "
                           "fixed read to time)")
    scene = load_scene(params["sim"]["scene"])
    now = [0.0]
    src = LoopedSkinCanSource(scene, speed=1.0, chunk_s=2.0, clock=lambda: now[0])
    src.open()
    reads = []
    for _ in range(int(round((1.0 + seconds) / period))):
        now[0] += period
        reads.append(src.recv_batch(1 << 22, 0.0))
    return reads[int(round(1.0 / period)):], scene.robot, period, batch


@contextmanager
def _compiled(on: bool) -> Iterator[None]:
    """The compiled decoding and tracking switched on or off for the block."""
    from tactile_descriptors_ros.codecs import sequence, skin_can

    before = skin_can.COMPILED_DECODE, sequence.COMPILED_TRACKING
    skin_can.COMPILED_DECODE = sequence.COMPILED_TRACKING = on
    try:
        yield
    finally:
        skin_can.COMPILED_DECODE, sequence.COMPILED_TRACKING = before


def _run(robot, reads: list[np.ndarray], batch_s: float, compiled: bool) -> tuple[float, list, dict]:
    """One pass of the driver's read path over ``reads``; its thread's CPU time, the messages and counters."""
    from tactile_descriptors_ros.codecs.skin_can import SkinCanDecoder, load_compiled
    from tactile_descriptors_ros.nodes.conversions import skin_part_to_msg
    from tactile_descriptors_ros.streams.skin import SkinStream

    ct = next(iter(robot.cell_types.values()))
    cells = {c.id: (bp.name, f"cell_{c.id}") for bp in robot.body_parts for c in bp.cells}
    faults: Counter = Counter()
    stream = SkinStream(cells, ct.vibration.rate_hz, ct.deformation.rate_hz, batch_s, "device", 1.0, 0.0,
                        time.time_ns, faults, lambda level, text: None, scales=(1.0, 1.0, 0.0))
    decoder = SkinCanDecoder(known_cell_ids=set(cells), rates_hz=stream.rates_hz())
    msgs = []
    with _compiled(compiled):
        load_compiled()
        c = time.thread_time()
        for frames in reads:
            batch = decoder.decode_frames(frames, time.time_ns())
            msgs += [skin_part_to_msg(part) for part in stream.add_parts(batch, time.time_ns())]
        cpu = time.thread_time() - c
    counters = {"decoder": decoder.stats, "stream_faults": dict(faults), "lost": stream.tracker.lost}
    return cpu, msgs, counters


def _same(a, b) -> bool:
    """Two messages field by field, floats bit for bit.  (Not their CDR serialisation: rclpy leaves the
    alignment padding uninitialised, so one message serialised twice can differ.)"""
    for name in a.get_fields_and_field_types():
        x, y = getattr(a, name), getattr(b, name)
        if name == "header":
            if (x.stamp.sec, x.stamp.nanosec, x.frame_id) != (y.stamp.sec, y.stamp.nanosec, y.frame_id):
                return False
        elif isinstance(x, str):
            if x != y:
                return False
        else:
            x, y = np.asarray(x), np.asarray(y)
            if x.dtype != y.dtype or x.shape != y.shape or x.tobytes() != y.tobytes():
                return False
    return True


def read_cost(n_cells: int = 200, *, parts: int = 1, read_period_s: float | None = None,
              batch_s: float | None = None, seconds: float = 4.0, repeat: int = 3) -> dict:
    """CPU per read of the skin driver's read path, compiled and numpy (module docstring).

    Parameters
    ----------
    n_cells : int
        Skin cells on the bus.
    parts : int
        Body parts they make (the NAO's 116 cells make 7): a message per body part and batch.
    read_period_s : float, optional
        Scene time between reads (default: the NAO graph's drivers').
    batch_s : float, optional
        The body part messages' batch (default: the NAO graph's).
    seconds : float
        Scene time read per run.
    repeat : int
        Runs of each path, alternating; the minimum is reported.

    Returns
    -------
    dict
        ``cells``, ``parts``, ``reads``, ``frames``, ``messages``, ``ms_per_read`` and
        ``ms_per_cell_second`` per path (``compiled``, ``numpy``), ``speedup``
        (numpy over compiled) and ``same_messages`` (checked before timing).

    Raises
    ------
    RuntimeError
        When the two paths give different messages or counters, without the compiled backend, or for a read
        period of 0.
    """
    from tactile_descriptors_ros.core import fast

    if fast.kernel_module() is None:
        raise RuntimeError("the compiled backend is not loaded (TACTILE_NO_NUMBA or numba missing)")
    with tempfile.TemporaryDirectory() as tmp:
        reads, robot, read_period_s, batch_s = _reads(n_cells, read_period_s, batch_s, seconds, tmp, parts)
    _, want, want_counters = _run(robot, reads, batch_s, compiled=False)
    _, got, got_counters = _run(robot, reads, batch_s, compiled=True)
    if len(got) != len(want) or not all(_same(a, b) for a, b in zip(got, want)) or got_counters != want_counters:
        raise RuntimeError("compiled and numpy read paths disagree: nothing timed")
    best = {"compiled": np.inf, "numpy": np.inf}
    for _ in range(repeat):
        for key in best:
            best[key] = min(best[key], _run(robot, reads, batch_s, compiled=key == "compiled")[0])
    data_s = len(reads) * read_period_s
    return {"cells": n_cells, "parts": parts, "read_period_s": read_period_s, "batch_s": batch_s, "reads": len(reads),
            "frames": int(sum(r.size for r in reads)), "messages": len(want), "same_messages": True,
            "ms_per_read": {k: 1e3 * v / len(reads) for k, v in best.items()},
            "ms_per_cell_second": {k: 1e3 * v / (n_cells * data_s) for k, v in best.items()},
            "speedup": best["numpy"] / best["compiled"]}


def format_read_cost(r: dict) -> str:
    """The result as text."""
    per, cell = r["ms_per_read"], r["ms_per_cell_second"]
    return "\n".join([
        f"skin driver read path, {r['cells']} cells in {r['parts']} body part(s), a read every "
        f"{1e3 * r['read_period_s']:g} ms of scene time "
        f"({r['reads']} reads, {r['frames']} CAN frames, {r['messages']} body part messages; both paths gave the "
        "same messages and counters):",
        f"  compiled decoding and tracking: {per['compiled']:.3f} ms per read, {cell['compiled']:.3f} ms per cell "
        "and second of data",
        f"  numpy:                          {per['numpy']:.3f} ms per read, {cell['numpy']:.3f} ms per cell and "
        "second of data",
        f"  numpy / compiled: {r['speedup']:.2f}x"])
