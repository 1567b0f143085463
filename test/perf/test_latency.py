"""``tactile bench --latency``: frames through window_node + classifier_node to a Prediction."""

from __future__ import annotations

import pytest

from tactile_descriptors_ros.perf import bench


@pytest.mark.ros
def test_latency_through_the_node_graph_in_process():
    from tactile_descriptors_ros.perf.latency import TARGET_MS, measure_latency

    res = measure_latency(duration_s=3.5, batch_s=0.05, lateness_s=0.05, in_process=True, micro=False)
    assert res["messages"] == 70 * 116
    assert res["predictions"] >= 1
    e2e, wait, proc = res["e2e"], res["wait"], res["processing"]
    assert e2e["n"] >= 1 and e2e["median_ms"] > 0
    # the window closes only once the batch holding end + lateness was acquired
    assert wait["median_ms"] >= 50.0
    # per prediction, end-to-end = waiting for the closing batch + processing it (each list rounded to 0.01 ms)
    assert len(res["e2e_ms"]) == len(res["wait_ms"]) == len(res["processing_ms"]) == e2e["n"]
    for total, waited, processed in zip(res["e2e_ms"], res["wait_ms"], res["processing_ms"]):
        assert total == pytest.approx(waited + processed, abs=0.02)
        assert processed > 0.0                     # a prediction never arrives before its closing batch was sent
    assert min(res["wait_ms"]) >= 50.0 - 0.01        # every window waited for end + lateness
    assert res["target_ms"] == TARGET_MS and res["target_met"] == (e2e["median_ms"] <= TARGET_MS)
    assert res["settings"]["batch_s"] == 0.05 and res["settings"]["messages_per_s"] == pytest.approx(2320)
    # one prediction per window: the last prediction of a window is the only one
    assert res["complete"]["n"] == e2e["n"]
    assert res["window_cpu_us_per_message"] > 0 and len(res["load_average"]["before"]) == 3
    # the window node's diagnostics arrived (faults counted, frames taken per callback)
    assert res["frames_per_callback"] is not None and res["frames_per_callback"] >= 1.0
    assert isinstance(res["window_faults"], dict)
    text = bench.format_report(bench.BenchReport([], [], None, {"numpy": "x", "cpus": 2, "load_average": [0]},
                                                 latency=res))
    assert "Prediction received" in text


@pytest.mark.ros
def test_split_window_nodes_need_processes():
    from tactile_descriptors_ros.perf.latency import measure_latency

    with pytest.raises(ValueError, match="split_window_nodes"):
        measure_latency(in_process=True, split_window_nodes=True)


@pytest.mark.ros
def test_message_cost_reports_each_step_per_message():
    from tactile_descriptors_ros.perf.latency import message_cost

    res = message_cost(batch_s=0.02, rounds=3, repeat=1)
    assert res["messages"] == 3 * 116
    per = res["us_per_message"]
    assert set(per) == {"deserialize", "convert", "add_poll", "add_many_poll"}
    assert all(v > 0 for v in per.values())
    assert res["us_per_message_batched"] == pytest.approx(per["deserialize"] + per["convert"] + per["add_many_poll"])
