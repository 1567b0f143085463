"""The garbage collector's pauses in this process, measured, and a heap settled after start-up.

CPython's cyclic garbage collector stops the interpreter while it scans a generation
of container objects.  Young generations are small and their collections take
microseconds; a full (generation 2) collection scans every tracked object of the
process.  A node that has imported rclpy, numpy and the compiled kernels (numba,
llvmlite) holds about 160,000 of them, and one full collection of that heap took
66-70 ms on a 2-core machine: for a driver that is that long without reading its bus,
for a window node that long without describing.  Almost all of those objects are
made at start-up and live as long as the process, so :func:`settle_heap` collects
once and moves the survivors to the permanent generation (:func:`gc.freeze`), which
no later collection scans; the collector stays on for whatever the running node
makes.  Freezing does not leak: frozen objects are still freed by reference counting;
only a cycle among them would outlive its use.

:class:`GcPauses` measures what the collector costs while the process runs, with
:data:`gc.callbacks` (the interpreter calls them at the start and the end of every
collection), so that a node's ``/diagnostics`` show each generation's collections and
their longest pause.  Nothing here imports ROS.
"""

from __future__ import annotations

import gc
import threading
import time
from collections.abc import Callable
from typing import Any

__all__ = ["GcPauses", "settle_heap"]

#: The generations of CPython's collector.
GENERATIONS = (0, 1, 2)


def settle_heap() -> dict[str, float]:
    """Collect everything once and freeze what survives (call once the process has started up).

    Returns
    -------
    dict
        ``collect_ms`` (the one full collection), ``frozen`` (objects moved to the
        permanent generation, all of them since the interpreter started) and
        ``tracked`` (objects a full collection still scans afterwards: those made since).
    """
    started = time.perf_counter_ns()
    gc.collect()
    collect_ms = (time.perf_counter_ns() - started) / 1e6
    gc.freeze()
    return {"collect_ms": collect_ms, "frozen": float(gc.get_freeze_count()),
            "tracked": float(len(gc.get_objects()))}


class GcPauses:
    """Count the collector's runs by generation and time their pauses.

    Parameters
    ----------
    clock_ns : callable
        A monotonic clock in nanoseconds (:func:`time.perf_counter_ns`).

    Notes
    -----
    A pause is the time between the interpreter's ``start`` and ``stop`` callbacks of
    one collection (the callbacks run in the thread that triggered it, with the GIL
    held).  :meth:`snapshot` is safe to call from any thread.  The lock is re-entrant:
    any allocation, also one made while a thread holds it (:meth:`snapshot` builds a
    dict), may start a collection whose callback takes it again in the same thread; a
    plain lock deadlocks the process there.
    """

    def __init__(self, clock_ns: Callable[[], int] = time.perf_counter_ns) -> None:
        self._clock_ns = clock_ns
        self._lock = threading.RLock()  # re-entered by a collection that starts while it is held
        self._started_ns: int | None = None
        self.reset()
        self._installed = False
        #: the one collection of :func:`settle_heap` [ms] (``None``: the heap was not settled)
        self.settle_ms: float | None = None
        #: objects :func:`settle_heap` moved to the permanent generation (0: the heap was not settled)
        self.frozen = 0

    def install(self) -> GcPauses:
        """Start measuring (idempotent); returns ``self``."""
        if not self._installed:
            gc.callbacks.append(self._on_gc)
            self._installed = True
        return self

    def uninstall(self) -> None:
        """Stop measuring."""
        if self._installed:
            gc.callbacks.remove(self._on_gc)
            self._installed = False

    def reset(self) -> None:
        """Forget the collections so far (those of start-up, before the process does its work)."""
        with self._lock:
            self.collections = [0] * len(GENERATIONS)
            self.total_ms = [0.0] * len(GENERATIONS)
            self.max_ms = [0.0] * len(GENERATIONS)
            self.collected = 0

    def settle(self) -> dict[str, float]:
        """:func:`settle_heap`, then :meth:`reset`: the collections counted from here on are the running
        process's; the settling collection's pause is ``gc_settle_ms``."""
        settled = settle_heap()
        self.reset()
        self.settle_ms = settled["collect_ms"]
        self.frozen = int(settled["frozen"])
        return settled

    def _on_gc(self, phase: str, info: dict[str, Any]) -> None:
        if phase == "start":
            self._started_ns = self._clock_ns()
            return
        if self._started_ns is None:  # installed during a collection
            return
        pause_ms = (self._clock_ns() - self._started_ns) / 1e6
        self._started_ns = None
        g = int(info.get("generation", 2))
        with self._lock:
            self.collections[g] += 1
            self.total_ms[g] += pause_ms
            self.max_ms[g] = max(self.max_ms[g], pause_ms)
            self.collected += int(info.get("collected", 0))

    def snapshot(self) -> dict[str, float | int]:
        """The counts and pauses so far, flat, for a diagnostic status.

        ``gc_collections_g<N>`` and ``gc_max_ms_g<N>`` per generation,
        ``gc_pause_ms_total`` over all of them, ``gc_collected`` (objects the
        collector freed), ``gc_settle_ms`` (the collection of :meth:`settle`, not
        counted in the others) and ``gc_frozen`` (objects :meth:`settle` moved
        to the permanent generation, which no collection scans).  That count is
        the one taken when settling, not counted again: :func:`gc.get_freeze_count`
        walks the whole permanent generation, 2 ms for 78,000 objects, and in a
        window node's diagnostics that walk was 4.6 % of its CPU.
        """
        with self._lock:
            out: dict[str, float | int] = {}
            for g in GENERATIONS:
                out[f"gc_collections_g{g}"] = self.collections[g]
                out[f"gc_max_ms_g{g}"] = round(self.max_ms[g], 3)
            out["gc_pause_ms_total"] = round(sum(self.total_ms), 3)
            out["gc_collected"] = self.collected
        if self.settle_ms is not None:
            out["gc_settle_ms"] = round(self.settle_ms, 3)
        out["gc_frozen"] = self.frozen
        return out
