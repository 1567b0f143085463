"""``tactile bench --latency``: frames through window_node + classifier_node to a Prediction."""

from __future__ import annotations

import pytest

from tactile_descriptors_ros.perf import bench


@pytest.mark.ros
def test_latency_through_the_node_graph_in_process():
    from tactile_descriptors_ros.perf.latency import measure_latency

    res = measure_latency(duration_s=3.5, batch_s=0.05, lateness_s=0.05, in_process=True)
    assert res["messages"] == 70 * 116
    assert res["predictions"] >= 1
    e2e, wait, proc = res["e2e"], res["wait"], res["processing"]
    assert e2e["n"] >= 1 and e2e["median_ms"] > 0
    # the window closes only once the batch holding end + lateness was acquired
    assert wait["median_ms"] >= 50.0
    assert proc["median_ms"] == pytest.approx(e2e["median_ms"] - wait["median_ms"], abs=wait["max_ms"])
    text = bench.format_report(bench.BenchReport([], [], None, {"numpy": "x", "cpus": 2, "load_average": [0]},
                                                 latency=res))
    assert "Prediction received" in text
