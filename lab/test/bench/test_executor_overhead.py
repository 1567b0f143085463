"""``tactile bench --executor-overhead``: each executor's CPU per message taken, every message checked first."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from tactile_descriptors_lab.bench.executor_overhead import format_executor_overhead


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.timeout(600)
def test_executor_overhead_bench_runs_both_executors_alternating_on_every_message():
    out = subprocess.run([sys.executable, "-m", "tactile_descriptors_ros.tools.cli", "bench", "--executor-overhead",
                          "--rounds", "1", "--seconds", "2", "--json"], capture_output=True, text=True, timeout=500)
    assert out.returncode == 0, out.stderr[-3000:]
    r = json.loads(out.stdout)
    assert [run["executor"] for run in r["runs"]] == ["single", "events"]
    for run in r["runs"]:  # every message arrived once, in order, as sent; the CPU between the first and last
        assert run["received"] == run["expected"] == 1400 and run["in_order"] and run["equal"]
        assert run["cpu_us_per_message"] == pytest.approx(1e6 * run["cpu_s"] / 1399) and run["cpu_s"] > 0
    per = r["cpu_us_per_message"]
    assert per == {run["executor"]: run["cpu_us_per_message"] for run in r["runs"]}
    assert r["events_over_single"] == pytest.approx(per["events"] / per["single"])
    assert "events / single" in format_executor_overhead(r)


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.timeout(600)
def test_executor_overhead_bench_takes_the_frames_as_bytes_too():
    """``--serialized``: each executor takes the frames built by rclpy and as their bytes read by the compiled
    pass, in turn; every message arrives, in order, equal to what was sent, either way."""
    from tactile_descriptors_ros.codecs import cdr

    if not cdr.load_compiled():
        pytest.skip("no compiled backend")
    out = subprocess.run([sys.executable, "-m", "tactile_descriptors_ros.tools.cli", "bench", "--executor-overhead",
                          "--serialized", "--rounds", "1", "--seconds", "1", "--json"], capture_output=True, text=True,
                         timeout=500)
    assert out.returncode == 0, out.stderr[-3000:]
    r = json.loads(out.stdout)
    assert [(run["executor"], run["taken"]) for run in r["runs"]] == [
        ("single", "message"), ("single", "bytes"), ("events", "message"), ("events", "bytes")]
    for run in r["runs"]:
        assert run["received"] == run["expected"] == 700 and run["in_order"] and run["equal"]
    per = r["cpu_us_per_message"]
    assert set(per) == {"single", "single, bytes", "events", "events, bytes"}
    assert r["bytes_over_message"] == {k: pytest.approx(per[f"{k}, bytes"] / per[k]) for k in ("single", "events")}
    assert "events: bytes / message" in format_executor_overhead(r)


def test_a_bad_count_of_rounds_is_refused():
    out = subprocess.run([sys.executable, "-m", "tactile_descriptors_ros.tools.cli", "bench", "--executor-overhead",
                          "--rounds", "0"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 2 and "--rounds and --seconds must be positive" in out.stderr
