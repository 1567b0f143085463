"""The skin driver's read path in one process: CPU per read with compiled decoding and stamping against numpy's.

``tactile bench --read-cost`` plays the scale graph's looped scene
(:func:`~tactile_descriptors_ros.sim.synthetic.scale_robot_files`: N cells of
the NAO's skin cell sliding over cork) as CAN frames and runs what the skin
driver's reader thread runs on every read, without ROS: the simulated bus
hands out the frames due in ``read_period_s`` of scene time
(:class:`~tactile_descriptors_ros.sim.sources.LoopedSkinCanSource` on a
stepped clock), :meth:`~tactile_descriptors_ros.codecs.skin_can.SkinCanDecoder.decode_frames`
decodes them, :meth:`~tactile_descriptors_ros.streams.skin.SkinStream.add_parts`
stamps and cuts them into body part messages and
:func:`~tactile_descriptors_ros.codecs.cdr.write_skin_part` writes each
message's bytes (publishing is left out: that is the middleware's).

Three paths over the same reads, alternating, in one run (:data:`PATHS`):
everything compiled; the compiled decoding and sequence tracking
(:data:`~tactile_descriptors_ros.codecs.skin_can.COMPILED_DECODE`,
:data:`~tactile_descriptors_ros.codecs.sequence.COMPILED_TRACKING`) with the
stream's stamping in numpy (:data:`~tactile_descriptors_ros.streams.skin.COMPILED_STAMPING`
off); and numpy throughout.  Before anything is timed every path must give
the numpy path's bytes and counters (the run stops otherwise).  Reported:
CPU time of the thread per read and per cell and second of data, the minimum
over ``repeat`` runs of each path (this machine is shared), and their ratios.
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


#: The host clock's start in the runs [ns since the epoch].
_HOST_T0_NS = 1_700_000_000 * 10**9
#: The paths timed: whether the decoding and tracking, and the stream's stamping, are compiled.
PATHS = {"compiled": (True, True), "without_stamping": (True, False), "numpy": (False, False)}


@contextmanager
def _compiled(path: str) -> Iterator[None]:
    """The compiled decoding, tracking and stamping switched on or off for the block, as ``PATHS[path]`` says."""
    from tactile_descriptors_ros.codecs import sequence, skin_can
    from tactile_descriptors_ros.streams import skin

    before = skin_can.COMPILED_DECODE, sequence.COMPILED_TRACKING, skin.COMPILED_STAMPING
    decoding, stamping = PATHS[path]
    skin_can.COMPILED_DECODE = sequence.COMPILED_TRACKING = decoding
    skin.COMPILED_STAMPING = stamping
    try:
        yield
    finally:
        skin_can.COMPILED_DECODE, sequence.COMPILED_TRACKING, skin.COMPILED_STAMPING = before


def _run(robot, reads: list[np.ndarray], read_period_s: float, batch_s: float, stamp_source: str, path: str
         ) -> tuple[float, list, dict]:
    """One pass of the driver's read path over ``reads``; its thread's CPU time, the messages' bytes and the
    counters.  The host clock steps a read period per read (each run stamps alike)."""
    from tactile_descriptors_ros.codecs.cdr import load_compiled as load_cdr
    from tactile_descriptors_ros.codecs.cdr import write_skin_part
    from tactile_descriptors_ros.codecs.skin_can import SkinCanDecoder, load_compiled
    from tactile_descriptors_ros.streams.skin import SkinStream

    ct = next(iter(robot.cell_types.values()))
    cells = {c.id: (bp.name, f"cell_{c.id}") for bp in robot.body_parts for c in bp.cells}
    faults: Counter = Counter()
    host = {"ns": _HOST_T0_NS}
    stream = SkinStream(cells, ct.vibration.rate_hz, ct.deformation.rate_hz, batch_s, stamp_source, 1.0, 0.0,
                        lambda: host["ns"], faults, lambda level, text: None, scales=(1.0, 1.0, 0.0))
    decoder = SkinCanDecoder(known_cell_ids=set(cells), rates_hz=stream.rates_hz())
    step_ns = int(round(read_period_s * 1e9))
    msgs = []
    with _compiled(path):
        load_compiled()
        load_cdr()
        c = time.thread_time()
        for frames in reads:
            host["ns"] += step_ns
            batch = decoder.decode_frames(frames, host["ns"])
            msgs += [write_skin_part(part, part.body_part) for part in stream.add_parts(batch, host["ns"])]
        cpu = time.thread_time() - c
    counters = {"decoder": decoder.stats, "stream_faults": dict(faults), "lost": stream.tracker.lost}
    return cpu, msgs, counters


def read_cost(n_cells: int = 200, *, parts: int = 1, read_period_s: float | None = None,
              batch_s: float | None = None, seconds: float = 4.0, repeat: int = 3,
              stamp_source: str = "device") -> dict:
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
    stamp_source : {"device", "clock"}
        The stream's stamps: the simulated graphs' drivers (scale graph, soak, demo) take the simulator's bus
        times (``device``), a robot's estimates them on the host clock (``clock``, the default of a driver).

    Returns
    -------
    dict
        ``cells``, ``parts``, ``stamp_source``, ``reads``, ``frames``, ``messages``, ``ms_per_read`` and
        ``ms_per_cell_second`` per path (:data:`PATHS`: ``compiled``, ``without_stamping``, ``numpy``),
        ``speedup`` (numpy over compiled), ``stamping_speedup`` (without stamping over compiled) and
        ``same_messages`` (checked before timing).

    Raises
    ------
    RuntimeError
        When the paths give different messages or counters, without the compiled backend, or for a read
        period of 0.
    """
    from tactile_descriptors_ros.core import fast

    if fast.kernel_module() is None:
        raise RuntimeError("the compiled backend is not loaded (TACTILE_NO_NUMBA or numba missing)")
    with tempfile.TemporaryDirectory() as tmp:
        reads, robot, read_period_s, batch_s = _reads(n_cells, read_period_s, batch_s, seconds, tmp, parts)
    _, want, want_counters = _run(robot, reads, read_period_s, batch_s, stamp_source, "numpy")
    for path in (p for p in PATHS if p != "numpy"):  # each against numpy's messages
        _, got, got_counters = _run(robot, reads, read_period_s, batch_s, stamp_source, path)
        if got != want or got_counters != want_counters:
            raise RuntimeError(f"the {path} and numpy read paths disagree: nothing timed")
    best = dict.fromkeys(PATHS, np.inf)
    for _ in range(repeat):
        for key in best:
            best[key] = min(best[key], _run(robot, reads, read_period_s, batch_s, stamp_source, key)[0])
    data_s = len(reads) * read_period_s
    return {"cells": n_cells, "parts": parts, "stamp_source": stamp_source, "read_period_s": read_period_s,
            "batch_s": batch_s, "reads": len(reads),
            "frames": int(sum(r.size for r in reads)), "messages": len(want), "same_messages": True,
            "ms_per_read": {k: 1e3 * v / len(reads) for k, v in best.items()},
            "ms_per_cell_second": {k: 1e3 * v / (n_cells * data_s) for k, v in best.items()},
            "speedup": best["numpy"] / best["compiled"],
            "stamping_speedup": best["without_stamping"] / best["compiled"]}


def format_read_cost(r: dict) -> str:
    """The result as text."""
    per, cell = r["ms_per_read"], r["ms_per_cell_second"]
    names = {"compiled": "compiled throughout:", "without_stamping": "compiled, numpy stamping:",
             "numpy": "numpy throughout:"}
    return "\n".join([
        f"skin driver read path, {r['cells']} cells in {r['parts']} body part(s), {r['stamp_source']} stamps, a "
        f"read every {1e3 * r['read_period_s']:g} ms of scene time "
        f"({r['reads']} reads, {r['frames']} CAN frames, {r['messages']} body part messages; every path gave the "
        "same bytes and counters):",
        *(f"  {names[k]:<27}{per[k]:.3f} ms per read, {cell[k]:.3f} ms per cell and second of data" for k in names),
        f"  numpy / compiled: {r['speedup']:.2f}x; numpy stamping / compiled: {r['stamping_speedup']:.2f}x"])
