"""The garbage collector's pauses, measured, and the start-up heap frozen (core/pauses.py)."""

from __future__ import annotations

import gc
import subprocess
import sys
import textwrap

import pytest

from tactile_descriptors_ros.core.pauses import GcPauses, settle_heap


class _Cycle:
    def __init__(self) -> None:
        self.me = self


def test_a_pause_is_the_time_between_the_interpreters_start_and_stop_calls():
    ticks = iter([1_000_000, 6_000_000, 10_000_000, 10_500_000])
    pauses = GcPauses(clock_ns=lambda: next(ticks))
    pauses._on_gc("start", {"generation": 2})
    pauses._on_gc("stop", {"generation": 2, "collected": 7})
    pauses._on_gc("start", {"generation": 0})
    pauses._on_gc("stop", {"generation": 0, "collected": 1})
    snap = pauses.snapshot()
    assert snap["gc_collections_g2"] == 1 and snap["gc_collections_g0"] == 1 and snap["gc_collections_g1"] == 0
    assert snap["gc_max_ms_g2"] == pytest.approx(5.0)
    assert snap["gc_max_ms_g0"] == pytest.approx(0.5)
    assert snap["gc_pause_ms_total"] == pytest.approx(5.5)
    assert snap["gc_collected"] == 8


def test_a_stop_without_its_start_is_not_a_pause():
    pauses = GcPauses(clock_ns=lambda: 0)
    pauses._on_gc("stop", {"generation": 2, "collected": 3})  # installed while a collection ran
    assert pauses.snapshot()["gc_collections_g2"] == 0


def test_real_collections_are_counted_by_generation_until_uninstalled():
    pauses = GcPauses().install()
    try:
        pauses.install()  # idempotent: one callback
        assert gc.callbacks.count(pauses._on_gc) == 1
        before = pauses.snapshot()
        for _ in range(3):
            _Cycle()
        gc.collect(1)
        gc.collect(2)
        after = pauses.snapshot()
        assert after["gc_collections_g1"] == before["gc_collections_g1"] + 1
        assert after["gc_collections_g2"] == before["gc_collections_g2"] + 1
        assert after["gc_collected"] >= before["gc_collected"] + 3  # the three cycles
        assert after["gc_max_ms_g2"] > 0.0
    finally:
        pauses.uninstall()
    assert pauses._on_gc not in gc.callbacks
    gc.collect(2)
    assert pauses.snapshot()["gc_collections_g2"] == after["gc_collections_g2"]


def test_a_settled_heap_leaves_a_full_collection_only_what_came_after():
    scanned_before = len(gc.get_objects())
    try:
        settled = settle_heap()
        assert settled["frozen"] == gc.get_freeze_count() >= scanned_before // 2
        assert settled["tracked"] < scanned_before / 20  # what a full collection still scans
        young = [[i] for i in range(1000)]  # made after: scanned, and collected when it is garbage
        assert len(gc.get_objects()) >= settled["tracked"] + 1000
        del young
        cycle = _Cycle()
        del cycle
        assert gc.collect() >= 1  # the collector still runs for what the running process makes
    finally:
        gc.unfreeze()
    assert gc.get_freeze_count() == 0


def test_settling_resets_the_counts_and_reports_its_own_collection_apart():
    pauses = GcPauses().install()
    try:
        gc.collect(2)
        assert pauses.snapshot()["gc_collections_g2"] >= 1
        settled = pauses.settle()
        snap = pauses.snapshot()
        assert snap["gc_collections_g2"] == snap["gc_collections_g1"] == snap["gc_collections_g0"] == 0
        assert snap["gc_pause_ms_total"] == 0.0 and snap["gc_max_ms_g2"] == 0.0
        assert snap["gc_settle_ms"] == pytest.approx(settled["collect_ms"], abs=1e-3) and snap["gc_settle_ms"] > 0
        assert snap["gc_frozen"] == settled["frozen"] > 0
        gc.collect(2)
        assert pauses.snapshot()["gc_collections_g2"] == 1
    finally:
        pauses.uninstall()
        gc.unfreeze()


def test_a_collection_that_starts_inside_a_snapshot_does_not_deadlock():
    # a collection after every allocation: the dict a snapshot builds while holding the lock starts one,
    # whose stop callback takes the lock again in the same thread (a plain lock never returned here)
    code = textwrap.dedent("""
        import gc
        from tactile_descriptors_ros.core.pauses import GcPauses
        pauses = GcPauses().install()
        gc.set_threshold(1)
        for _ in range(2000):
            snap = pauses.snapshot()
            pauses.reset()
        gc.set_threshold(700)
        print(snap["gc_collections_g0"] + snap["gc_collections_g1"] + snap["gc_collections_g2"])
    """)
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert int(done.stdout) >= 1  # collections did start inside the last snapshot


def test_a_snapshot_reports_the_settled_count_without_walking_the_permanent_generation(monkeypatch):
    # counting the permanent generation walks all of it (milliseconds a call for a node's heap)
    pauses = GcPauses()
    try:
        settled = pauses.settle()

        def walk() -> int:
            raise AssertionError("gc.get_freeze_count walks the permanent generation")

        monkeypatch.setattr(gc, "get_freeze_count", walk)
        assert pauses.snapshot()["gc_frozen"] == settled["frozen"] > 0
    finally:
        monkeypatch.undo()
        gc.unfreeze()
    assert GcPauses().snapshot()["gc_frozen"] == 0  # never settled: nothing frozen by it
