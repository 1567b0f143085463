"""Smoke test of ``tactile bench`` with tiny sizes (no timing assertions: timings are noisy)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tactile_descriptors_lab.bench import bench
from tactile_descriptors_ros.tools.cli import main


def test_bench_command_json_smoke(capsys):
    code = main(["bench", "--sizes", "130", "--lengths", "0.5", "--repeat", "1", "--baseline-cells", "3",
                 "--no-windowing", "--json"])
    assert code == 0
    report = json.loads(capsys.readouterr().out)
    names = [c["name"] for c in report["cases"]]
    assert names[0].startswith("shadow_hand") and names[1].startswith("nao") and "130 cells" in names[2]
    for case in report["cases"] + report["scaling"]:
        assert case["max_abs_diff"] < 1e-6  # agreement was checked before timing
        assert case["package"]["wall_ms"] > 0 and case["baseline"]["cpu_ms"] > 0
        assert case["speedup_cpu"] == pytest.approx(case["baseline"]["cpu_ms"] / case["package"]["cpu_ms"])
    assert report["cases"][2]["baseline_extrapolated_from"] == 3
    assert any("extrapolated" in note for note in report["notes"])
    assert report["scaling"][0]["length_s"] == pytest.approx(0.5)
    assert report["windowing"] is None and report["environment"]["threads"] == 1
    # which backend served, its load/compile time (before timing); the kernel checked against the reference
    accel = report["accelerator"]["accelerator"]
    assert accel in ("numba", "reference") and report["accelerator"]["first_call_s"] >= 0
    for case in report["cases"]:
        assert case["accelerator"] == accel and case["package_windows_per_s_cpu"] > 0
    for case in report["cases"][:2]:  # Shadow Hand and NAO: kernel against the reference, then the reference timed
        assert case["max_abs_diff_reference"] < 1e-6 and case["reference"]["cpu_ms"] > 0
    targets = report["targets"]
    assert set(targets) == {"shadow_hand_time", "nao_time", "nao_speedup", "skin_10000_time", "latency",
                            "latency_exploration", "latency_design_wait", "skin_10000_graph",
                            "skin_10000_graph_2_hosts", "view_overhead", "shadow_hand_best_mode_time",
                            "nao_best_mode_time"}
    # the shipped feature groups, checked against the evaluation's values before they were timed
    best = {b["key"]: b for b in report["best_mode"]}
    assert best["shadow_hand"]["groups"] == ["per_channel", "bands", "levels", "statistics"]
    assert best["shadow_hand"]["n_values"] == 5 * 261 and best["nao"]["n_values"] == 7 * 131
    for key, limit in (("shadow_hand", 2.0), ("nao", 10.0)):
        # judged on the path the window node runs: block averaging where the description ships it
        t = targets[f"{key}_best_mode_time"]
        shipped = best[key]["blocks"] if best[key]["blocks"] is not None else best[key]["package"]
        assert t["cpu_ms"] == shipped["cpu_ms"] and t["met"] == (t["cpu_ms"] <= limit)
        assert t["single_window_cpu_ms"] == best[key]["package"]["cpu_ms"]
        assert best[key]["met"] == t["met"]
        assert t["checked_max_abs_diff"] < 1e-6
    # the window node's path: the Shadow Hand averages 1 s blocks (timed beside one descriptor), the NAO does not
    hand = best["shadow_hand"]
    assert (hand["block_s"], hand["block_hop_s"]) == (1.0, 0.5) and hand["blocks"]["cpu_ms"] > 0
    assert hand["ratio_blocks_to_single_cpu"] == pytest.approx(hand["blocks"]["cpu_ms"] / hand["package"]["cpu_ms"])
    assert best["nao"]["blocks"] is None and best["nao"]["ratio_blocks_to_single_cpu"] is None
    assert targets["shadow_hand_time"]["met"] == (report["cases"][0]["package"]["cpu_ms"] <= 0.3)
    assert targets["nao_time"]["met"] == (report["cases"][1]["package"]["cpu_ms"] <= 2.0)
    assert targets["nao_speedup"]["speedup_cpu"] == pytest.approx(report["cases"][1]["speedup_cpu"])
    # the same windows described as the window node describes its own (from the window's stacks), beside
    for key, case in (("shadow_hand_time", report["cases"][0]), ("nao_time", report["cases"][1])):
        assert case["package_node"]["cpu_ms"] > 0 and targets[key]["node_path_cpu_ms"] == case["package_node"]["cpu_ms"]
    assert targets["skin_10000_time"]["met"] is None and targets["latency"]["met"] is None  # not measured
    assert targets["latency_exploration"]["met"] is None and targets["latency_design_wait"]["met"] is None
    assert targets["skin_10000_graph"]["met"] is None  # measured by tactile bench --scale-graph
    assert targets["skin_10000_graph_2_hosts"]["met"] is None  # ... --scale-graph --hosts 2
    assert targets["view_overhead"]["met"] is None  # measured by tactile bench --view-overhead


def test_bench_aborts_when_the_kernel_disagrees_with_the_reference(monkeypatch, capsys):
    real = bench.descriptors.cell_quantities

    def off(*args):
        out = list(real(*args))
        out[6] = out[6] + 1e-3  # Pearson
        return tuple(out)

    monkeypatch.setattr(bench.descriptors, "cell_quantities", off)
    code = main(["bench", "--sizes", "", "--lengths", "0.5", "--repeat", "1", "--no-windowing"])
    assert code == 1
    assert "kernel and reference disagree on lin" in capsys.readouterr().err


def test_bench_aborts_when_the_baseline_disagrees(monkeypatch, capsys):
    real = bench.naive_describe
    monkeypatch.setattr(bench, "naive_describe", lambda *a, **k: real(*a, **k) + 1e-3)
    code = main(["bench", "--sizes", "", "--lengths", "0.5", "--repeat", "1", "--no-windowing"])
    assert code == 1
    assert "disagree" in capsys.readouterr().err


def test_naive_baseline_equals_describe_window_on_both_robots():
    hand = bench.load_robot("shadow_hand")
    assert bench.check_agreement(hand, bench.biotac_window(hand, 0.5)) < 1e-9
    robot = bench.skin_robot(40, cells_per_part=16)
    assert len(robot.body_parts) == 3
    assert bench.check_agreement(robot, bench.skin_window(robot, 0.5, seed=2)) < 1e-9


def test_windowing_measurement_counts_messages():
    res = bench.bench_windowing(stream_s=2.6, message_ms=50.0)
    assert res.messages == 52 * 116 and res.messages_per_s_needed == pytest.approx(2320.0)
    assert res.us_per_message > 0 and 0 < res.core_fraction
    assert res.us_per_message_many > 0 and res.many_batch == 116
    assert res.windows == 2 and res.same_windows  # add_many cut the windows add did


def test_text_report_lists_every_case():
    hand = bench.load_robot("shadow_hand")
    with bench.one_core():
        case = bench.bench_case("hand", hand, bench.biotac_window(hand, 0.5), repeat=1, baseline_repeat=1,
                                target_ms=1.0)
    report = bench.BenchReport([case], [], None, {"numpy": np.__version__, "cpus": 2, "load_average": [0, 0, 0]})
    text = bench.format_report(report)
    assert "hand" in text and "target" in text and "accelerator" in text
    d = report.to_dict()
    assert json.dumps(d, default=float)
    assert d["targets"]["shadow_hand_time"]["met"] is None  # a case without the key is not a target case


def test_text_report_prints_the_latency_fields(monkeypatch, capsys):
    """``--latency`` flags reach measure_latency and its summary is printed (the ROS run itself is in test_latency)."""
    from tactile_descriptors_lab.bench import latency

    calls = []

    def fake(**kwargs):
        calls.append(kwargs)
        summary = {"n": 3, "median_ms": 96.0, "p95_ms": 113.0, "max_ms": 115.0}
        small = {"n": 3, "median_ms": 4.0, "p95_ms": 6.0, "max_ms": 7.0}
        return {"nodes": "processes", "cells": 116, "batch_s": 0.01, "lateness_s": 0.0, "predictions": 3,
                "mode": kwargs["mode"], "e2e": summary, "wait": summary, "processing": summary, "complete": summary,
                "parts_ms": {"design_wait": summary, "describe": small, "classifier": small},
                "window_cpu_us_per_message": 250.0, "window_cpu_fraction_of_core": 0.58,
                "frames_per_callback": 3.5, "window_faults": {"late": 2},
                "per_message": {"us_per_message": {"deserialize": 60.0, "convert": 50.0}},
                "design_wait_ms": 10.0, "design_wait_target_ms": 10.0, "target_ms": 20.0, "target_met": False}

    monkeypatch.setattr(latency, "measure_latency", fake)
    code = main(["bench", "--sizes", "130", "--lengths", "0.5", "--repeat", "1", "--baseline-cells", "3",
                 "--no-windowing", "--latency", "--latency-split-window-nodes", "--latency-drain-max", "0",
                 "--latency-no-micro"])
    assert code == 0
    assert [c["mode"] for c in calls] == ["fixed", "exploration"]  # both by default
    for seen in calls:
        assert seen["split_window_nodes"] is True and seen["drain_max"] == 0 and seen["micro"] is False
        assert seen["batch_s"] is None and seen["lateness_s"] is None  # the shipped graph's
    out = capsys.readouterr().out
    assert "window end stamp -> last Prediction of that window" in out
    assert "release decision -> last Prediction of that window" in out
    assert "window cut -> Descriptor published (in the node)" in out
    assert "window node CPU per message 250 us (58 % of one core)" in out
    assert "deserialize 60, convert 50" in out and "NOT met" in out
    assert "113.00 ms p95" in out  # the targets list the p95 of each run


def test_best_mode_check_refuses_a_live_call_that_differs_from_the_evaluation(monkeypatch):
    robot = bench.load_robot("shadow_hand")
    cells = bench.biotac_window(robot, 0.5)
    assert bench.check_against_evaluation(robot, cells, robot.descriptor.groups) < 1e-9
    real = bench.describe_window

    def skewed(robot_, cells_, **kw):
        d = real(robot_, cells_, **kw)
        if len(robot_.body_parts) == 5 and kw.get("groups") == robot.descriptor.groups:
            d.body_parts[2].values[100] *= 1.01  # one band value of one finger
        return d

    monkeypatch.setattr(bench, "describe_window", skewed)
    with pytest.raises(bench.BenchMismatch, match="middle: live call and evaluation disagree at bands/"):
        bench.check_against_evaluation(robot, cells, robot.descriptor.groups)


def test_latency_targets_are_judged_on_the_p95_and_the_design_wait():
    def run(p95, wait_ms):
        return {"e2e": {"n": 20, "median_ms": p95 / 2, "p95_ms": p95, "max_ms": p95 + 1},
                "parts_ms": {"design_wait": {"n": 20}}, "design_wait_ms": wait_ms}

    env = {"numpy": "x", "cpus": 2, "load_average": [0]}
    t = bench.targets(bench.BenchReport([], [], None, env, latency=run(19.5, 10.0),
                                        latency_exploration=run(20.5, 10.0)))
    assert t["latency"]["met"] is True and t["latency"]["p95_ms"] == 19.5 and t["latency"]["max_ms"] == 20.5
    assert t["latency_exploration"]["met"] is False  # the median (10.25 ms) is not what is judged
    assert t["latency"]["parts_ms"] == {"design_wait": {"n": 20}}
    assert t["latency_design_wait"] == {**t["latency_design_wait"], "design_wait_ms": 10.0, "met": True}
    slow = bench.targets(bench.BenchReport([], [], None, env, latency=run(15.0, 60.0)))
    assert slow["latency_design_wait"]["met"] is False and slow["latency_exploration"]["met"] is None


def test_the_node_path_is_timed_with_a_clock_per_cell_and_the_same_values():
    """The bench's window as the node holds it: no two cells share a stamp row (the kernel cannot reuse a
    cell's hold runs for the next), every cell's fast and slow stamps moved alike, so the descriptor is the
    simulator window's, bit for bit."""
    from tactile_descriptors_ros.core.aggregation import describe_window, stack_cells
    from tactile_descriptors_ros.core.robot import load_robot

    robot = load_robot("nao")
    cells = bench.skin_window(robot, 0.5)
    moved = bench.own_clocks(cells)
    assert moved.keys() == cells.keys()
    node_cells, stacks = stack_cells(robot, moved)
    for rows in (stacks.vibration_t_ns, stacks.deformation_t_ns):
        assert rows.ndim == 2 and (rows[1:] != rows[:-1]).all(axis=1).all()
    for cid, sig in cells.items():  # the samples untouched, the stamps of both modalities moved by one offset
        np.testing.assert_array_equal(moved[cid].vibration, sig.vibration)
        offset = moved[cid].vibration_t_ns - sig.vibration_t_ns
        assert (offset == offset[0]).all() and (moved[cid].deformation_t_ns - sig.deformation_t_ns == offset[0]).all()
    want = describe_window(robot, cells, channels="averaged")
    got = describe_window(robot, node_cells, channels="averaged", stacks=stacks)
    np.testing.assert_array_equal(got.values, want.values)
    assert [p.quality for p in got.body_parts] == [p.quality for p in want.body_parts]
