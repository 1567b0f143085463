"""``tactile bench --latency``: frames through window_node + classifier_node to a Prediction."""

from __future__ import annotations

import numpy as np
import pytest

from tactile_descriptors_lab.bench import bench


@pytest.mark.ros
def test_latency_through_the_node_graph_in_process():
    from tactile_descriptors_lab.bench.latency import TARGET_MS, measure_latency

    res = measure_latency(duration_s=3.5, batch_s=0.05, lateness_s=0.05, in_process=True, micro=False)
    assert res["messages"] == 70 * 7  # one SkinPartFrames per body part and batch (116 cells in 7 parts)
    # windows on the grid of the hop: 2 or 3 end in 3.5 s of data, as the probe's start falls on the grid
    assert res["predictions"] == res["expected_predictions"] >= 2
    e2e, wait, _proc = res["e2e"], res["wait"], res["processing"]
    assert e2e["n"] >= 1 and e2e["median_ms"] > 0
    # the window closes only once the batch holding end + lateness was acquired
    assert wait["median_ms"] >= 50.0
    # per prediction, end-to-end = waiting for the closing batch + processing it (each list rounded to 0.01 ms)
    assert len(res["e2e_ms"]) == len(res["wait_ms"]) == len(res["processing_ms"]) == e2e["n"]
    for total, waited, processed in zip(res["e2e_ms"], res["wait_ms"], res["processing_ms"]):
        assert total == pytest.approx(waited + processed, abs=0.02)
        assert processed > 0.0                     # a prediction never arrives before its closing batch was sent
    assert min(res["wait_ms"]) >= 50.0 - 0.01        # every window waited for end + lateness
    assert res["target_ms"] == TARGET_MS and res["target_met"] == (e2e["p95_ms"] <= TARGET_MS)
    # a window ends 1.5 ms (1.5 accelerometer periods) before a batch ends; end + lateness lies in the next batch
    assert res["design_wait_ms"] == pytest.approx(51.5) and res["mode"] == "fixed"
    # what each part costs: the descriptor of each window was seen on its way, the window node reported its timing
    parts = res["parts_ms"]
    assert parts["window_node"]["n"] == parts["classifier"]["n"] == e2e["n"]
    assert parts["describe"]["n"] >= 1 and parts["frames_age_at_window_node"]["n"] >= 1
    assert parts["cut"]["n"] >= 1 and 0.0 < parts["cut"]["median_ms"] <= parts["cut"]["max_ms"]
    for total, waited in zip(res["e2e_ms"], res["wait_ms"]):
        assert total >= waited
    # per prediction, its window node and classifier stages add up to its processing
    assert len(res["window_node_ms"]) == len(res["classifier_ms"]) == e2e["n"]
    for processed, node, classified in zip(res["processing_ms"], res["window_node_ms"], res["classifier_ms"]):
        assert processed == pytest.approx(node + classified, abs=0.03)
    # the window node rehearsed its describing path at its first frames, before its first window
    assert len(res["rehearsal_ms"]) == 1 and next(iter(res["rehearsal_ms"].values())) > 0.0
    assert res["settings"]["batch_s"] == 0.05 and res["settings"]["messages_per_s"] == pytest.approx(140)
    # one prediction per window: the last prediction of a window is the only one
    assert res["complete"]["n"] == e2e["n"]
    assert res["window_cpu_us_per_message"] > 0 and len(res["load_average"]["before"]) == 3
    # the window node's diagnostics arrived (faults counted, frames taken per callback)
    assert res["frames_per_callback"] is not None and res["frames_per_callback"] >= 1.0
    assert isinstance(res["window_faults"], dict)
    # windows closed from samples cut ahead (how many depends on how far behind the node ran: a window whose
    # samples came in one callback is cut whole), and the early cuts' cost
    heads = res["cut_ahead"]
    assert set(heads) == {"used", "recut"} and heads["used"] + heads["recut"] <= res["predictions"]
    assert parts["cut_ahead"]["n"] >= heads["used"]
    text = bench.format_report(bench.BenchReport([], [], None, {"numpy": "x", "cpus": 2, "load_average": [0]},
                                                 latency=res))
    assert "Prediction received" in text and "what each part costs" in text


@pytest.mark.ros
def test_exploration_latency_is_timed_from_the_release_decision():
    """Touch, let go, touch: each exploration's Prediction is timed from window end + release_s."""
    from tactile_descriptors_lab.bench.latency import (
        EXPLORATION_RELEASED_S,
        EXPLORATION_TOUCH_S,
        measure_latency,
    )
    from tactile_descriptors_ros.core.robot import load_robot

    # reliable frames: on a loaded machine the in-process node falls behind, and a lost release is no release
    res = measure_latency(duration_s=4.6, batch_s=0.01, lateness_s=0.0, mode="exploration", in_process=True,
                          window_parameters={"qos.frames.reliability": "reliable", "qos.frames.depth": 2000},
                          micro=False)
    assert res["mode"] == "exploration" and res["design_wait_ms"] == pytest.approx(10.0)
    release_ms = 1e3 * load_robot("nao").window.release_s
    assert res["settings"]["release_s"] == pytest.approx(release_ms / 1e3)
    # a touch of 1.2 s every 1.6 s, the first from 0.4 s: released at 1.6 and 3.2 s; the third touch is still on
    cycle_s = EXPLORATION_RELEASED_S + EXPLORATION_TOUCH_S
    assert res["expected_predictions"] == int((4.6 - EXPLORATION_RELEASED_S) // cycle_s) == 2
    assert res["predictions"] == res["expected_predictions"] == res["e2e"]["n"]
    for total, waited, processed in zip(res["e2e_ms"], res["wait_ms"], res["processing_ms"]):
        assert total == pytest.approx(waited + processed, abs=0.02) and processed > 0.0
        assert waited > 0.0  # the batch holding the release decision goes out after its samples were taken
    assert res["target_met"] == (res["e2e"]["p95_ms"] <= 20.0)
    # the window node's descriptions made during the release time (how many depends on how far behind it ran)
    ahead = res["described_ahead"]
    assert set(ahead) == {"used", "changed", "discarded"} and ahead["used"] + ahead["changed"] <= res["predictions"]


@pytest.mark.ros
def test_split_window_nodes_need_processes():
    from tactile_descriptors_lab.bench.latency import measure_latency

    with pytest.raises(ValueError, match="split_window_nodes"):
        measure_latency(in_process=True, split_window_nodes=True)


@pytest.mark.ros
def test_message_cost_reports_each_step_per_message():
    from tactile_descriptors_lab.bench.latency import message_cost

    res = message_cost(batch_s=0.05, rounds=50, repeat=1)  # 2.5 s of data: a 2 s window is cut
    assert res["messages"] == 50 * 7
    per = res["us_per_message"]
    assert set(per) == {"deserialize", "convert_part", "add_part_poll", "convert", "add_poll", "add_many_poll"}
    assert all(v > 0 for v in per.values())
    # the node's path: a body part's message in one piece
    assert res["us_per_message_batched"] == pytest.approx(per["deserialize"] + per["convert_part"]
                                                         + per["add_part_poll"])
    assert res["us_per_message_per_cell"] == pytest.approx(per["deserialize"] + per["convert"]
                                                          + min(per["add_poll"], per["add_many_poll"]))
    # every path is timed on the same data: each cuts the same window
    assert set(res["windows_cut"].values()) == {1}, res["windows_cut"]


@pytest.mark.ros
@pytest.mark.parametrize("mode", ["fixed", "exploration"])
def test_node_message_cost_times_the_window_nodes_own_callback(mode):
    from tactile_descriptors_lab.bench.latency import node_message_cost

    res = node_message_cost(mode=mode, rounds=60, warm_rounds=10)
    assert res["messages_timed"] == 50 * 7 and res["us_per_message"] > 0
    # the probe's messages are whole and in order: the node counts no fault
    assert res["faults"] and not any(res["faults"].values()), res["faults"]
    with pytest.raises(ValueError, match="warm_rounds"):
        node_message_cost(rounds=10, warm_rounds=10)


@pytest.mark.ros
def test_node_message_cost_hands_over_bytes_or_rclpys_messages():
    """``taken``: the CDR deserialised by rclpy inside the timing, or the bytes read by the node; either way
    every message is taken without a fault."""
    from tactile_descriptors_lab.bench.latency import contact_message_cost, node_message_cost

    for taken in ("rclpy", "bytes"):
        for res in (node_message_cost(rounds=30, warm_rounds=10, taken=taken),
                    contact_message_cost(rounds=30, warm_rounds=10, taken=taken)):
            assert res["taken"] == taken and res["messages_timed"] == 20 * 7 and res["us_per_message"] > 0
            assert not any(res["faults"].values()), res["faults"]
    with pytest.raises(ValueError, match="taken"):
        node_message_cost(rounds=30, warm_rounds=10, taken="serialised")


@pytest.mark.ros
def test_contact_message_cost_times_the_contact_nodes_own_callback():
    from tactile_descriptors_lab.bench.latency import contact_message_cost
    from tactile_descriptors_ros.core import contact

    for compiled in (True, False):
        res = contact_message_cost(rounds=30, warm_rounds=10, compiled=compiled)
        assert res["messages_timed"] == 20 * 7 and res["us_per_message"] > 0 and res["compiled"] is compiled
        # every cell touches in every message: a contact each, and no fault
        assert (res["contacts_published"], res["contacts_unsubscribed"]) == (30 * 7, 0) and res["faults"] == {}, res
    assert contact.COMPILED_SUMS is True  # switched back
    # as shipped (contact.lazy), with nobody subscribed: every message's contact counted, none published
    res = contact_message_cost(rounds=30, warm_rounds=10, lazy=True)
    assert res["lazy"] is True and res["messages_timed"] == 20 * 7
    assert (res["contacts_published"], res["contacts_unsubscribed"]) == (0, 30 * 7) and res["faults"] == {}, res


def test_the_shipped_graphs_fixed_windows_wait_only_the_margin_before_their_batch_ends():
    """The skin driver's batches end on whole multiples of ``batch_s`` in stamp time and fixed windows end
    1.5 accelerometer periods before a whole multiple of the hop: the batch with a window's last samples
    closes it.  A window ending on a batch boundary (no margin) waits for the whole next batch."""
    from tactile_descriptors_lab.bench.latency import _design_wait_ms, _expected_predictions, shipped_latency_settings
    from tactile_descriptors_ros.core.robot import load_robot
    from tactile_descriptors_ros.core.windowing import grid_margin_ns

    batch_s, lateness_s = shipped_latency_settings("nao")
    batch_ns, margin_ns = int(round(batch_s * 1e9)), grid_margin_ns(load_robot("nao"))
    assert (batch_s, lateness_s, margin_ns) == (0.01, 0.0, 1_500_000)
    start_ns = 1_234_567 * batch_ns  # the probe starts on the batch grid, anywhere on the hop's
    for offset_ns in (0, 130_000_000, 490_000_000):
        args = ("fixed", start_ns + offset_ns, 8_000_000_000, batch_ns, 2.0, 0.5, lateness_s)
        assert _design_wait_ms(*args, margin_ns) == pytest.approx(1.5)
        assert _design_wait_ms(*args, 0) == pytest.approx(10.0)
    # 8 s of data from a grid start: the windows that end by its last accelerometer sample (1 ms before its end)
    grid_start = 17 * 500_000_000 - margin_ns
    assert _expected_predictions("fixed", grid_start, 8_000_000_000, 2.0, 0.5, 0.0, 0, margin_ns) == 12
    assert _expected_predictions("fixed", grid_start + 1, 8_000_000_000, 2.0, 0.5, 0.0, 0, margin_ns) == 11


@pytest.mark.ros
def test_the_probe_gives_cells_clocks_of_their_own_and_their_fixed_windows_close():
    """With ``cell_phases`` every cell samples at its own instants within the accelerometer period (each body
    part's first on the grid); the windows still close, each once, with nothing counted as a fault."""
    from tactile_descriptors_lab.bench.latency import cell_phases_ns, measure_latency, probe_frames
    from tactile_descriptors_ros.core.robot import load_robot
    from tactile_descriptors_ros.nodes.conversions import skin_part_msg_to_part_chunk

    desc = load_robot("nao")
    phases = cell_phases_ns(desc, 3)
    assert all(0 <= v < 1_000_000 for v in phases.values()) and len(set(phases.values())) > 100
    assert all(phases[p.cells[0].id] == 0 for p in desc.body_parts)
    frames = probe_frames(desc, 0.01, 3, phases_ns=phases)
    for name, msg in frames.templates[1]:
        chunk = skin_part_msg_to_part_chunk(msg)
        n = chunk.vibration_count
        firsts = chunk.vibration_t_ns[np.concatenate([[0], np.cumsum(n)[:-1]])]
        assert (n == 10).all() and firsts.tolist() == [phases[int(c)] for c in chunk.cell_ids], name

    res = measure_latency(duration_s=3.0, batch_s=0.01, lateness_s=0.0, in_process=True, micro=False,
                          cell_phases=True, window_parameters={"qos.frames.reliability": "reliable",
                                                               "qos.frames.depth": 2000})
    assert res["settings"]["cell_phases"] is True
    assert res["predictions"] == res["expected_predictions"] >= 2 and not any(res["window_faults"].values())
    heads = res["cut_ahead"]
    assert heads["used"] + heads["recut"] <= res["predictions"]
