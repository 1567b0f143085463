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


def test_one_message_for_the_robot_holds_the_same_samples_as_one_per_body_part():
    """The probe's whole-robot batch is its body parts' batches joined in order: the same cells, samples and
    offsets (every part's message starts at the batch's first accelerometer sample)."""
    import numpy as np

    from tactile_descriptors_lab.bench.latency import probe_frames
    from tactile_descriptors_ros.core.robot import load_robot

    desc = load_robot("nao")
    parts, robot = probe_frames(desc, 0.01, 3), probe_frames(desc, 0.01, 3, whole_robot=True)
    assert len(parts.templates) == len(robot.templates) == 2  # 250 Hz force: 3 then 2 samples a batch
    for by_part, ((name, whole),) in zip(parts.templates, robot.templates):
        assert name == "" and [n for n, _ in by_part] == [p.name for p in desc.body_parts]
        for field in ("cell_ids", "accel_count", "force_count", "accel_x", "accel_z", "accel_offset_ns", "force",
                      "force_offset_ns"):
            joined = np.concatenate([np.asarray(getattr(m, field)) for _, m in by_part])
            assert np.array_equal(np.asarray(getattr(whole, field)), joined), field
        assert len(whole.cell_ids) == 116
        assert {m.header.stamp.nanosec for _, m in by_part} == {whole.header.stamp.nanosec}


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.timeout(600)
def test_executor_overhead_bench_compares_one_message_for_the_robot_with_one_per_body_part():
    """``--executor-layouts parts,robot``: the NAO's samples of a second as 700 body-part messages and as 100
    whole-robot ones, every message checked; CPU per cell-second from the CPU per message of each."""
    out = subprocess.run([sys.executable, "-m", "tactile_descriptors_ros.tools.cli", "bench", "--executor-overhead",
                          "--executor-layouts", "parts,robot", "--rounds", "1", "--seconds", "1", "--json"],
                         capture_output=True, text=True, timeout=500)
    assert out.returncode == 0, out.stderr[-3000:]
    r = json.loads(out.stdout)
    assert [(run["executor"], run["layout"]) for run in r["runs"]] == [
        ("single", "parts"), ("single", "robot"), ("events", "parts"), ("events", "robot")]
    for run in r["runs"]:
        assert run["received"] == run["expected"] == {"parts": 700, "robot": 100}[run["layout"]]
        assert run["in_order"] and run["equal"] and run["cells_per_batch"] == 116
        assert run["cpu_ms_per_cell_second"] == pytest.approx(run["cpu_us_per_message"] * run["rate_hz"] / 116e3)
        assert run["publisher_cpu_s"] > 0
    cs = r["cpu_ms_per_cell_second"]
    assert set(cs) == {"single, parts", "single, robot", "events, parts", "events, robot"}
    assert r["robot_over_parts"] == {k: pytest.approx(cs[f"{k}, robot"] / cs[f"{k}, parts"])
                                     for k in ("single", "events")}
    assert "one message for the robot / one per body part" in format_executor_overhead(r)


def test_an_unknown_layout_is_refused():
    out = subprocess.run([sys.executable, "-m", "tactile_descriptors_ros.tools.cli", "bench", "--executor-overhead",
                          "--executor-layouts", "parts,arm"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 2 and "argument --executor-layouts: expected layouts among part, parts, robot" in out.stderr
