"""``tactile bench --soak``: the graph at full rate, RSS and CPU per node, lost and late frames."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys

import pytest

from tactile_descriptors_lab.bench.soak import NodeSamples, SoakReport, format_soak, soak_scene


def test_growth_is_measured_after_the_first_minute_and_the_slope_per_minute():
    s = NodeSamples("window_node", "window_node", 1, t_s=[0, 30, 60, 120, 180], rss_mb=[10, 200, 200, 205, 210],
                    cpu_s=[0, 3, 6, 12, 18])
    assert s.growth_after_s(60.0) == pytest.approx(5.0)  # start-up (10 -> 200 MB) is not growth
    assert s.rate_mb_per_min(60.0) == pytest.approx(5.0)
    assert s.cpu_percent() == pytest.approx(10.0)
    assert NodeSamples("n", "n", 1, t_s=[0, 30], rss_mb=[1, 2], cpu_s=[0, 1]).growth_after_s(60.0) is None


def test_lost_and_late_frames_come_from_every_window_node_and_nothing_else():
    diag = {"window_node: windows": {"fault_lost_frames": "3", "fault_windower_gap": "2", "descriptors_published": "4"},
            "window_node_chest: windows": {"fault_lost_frames": "1", "fault_windower_out_of_order": "5"},
            "skin_driver: chest": {"lost_frames": "99"}}
    r = SoakReport("nao", 10.0, 10.0, 1.0, [], diag, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 2, 10, {})
    assert r.lost_frames()["lost_frames"] == 4 and r.late_frames()["windower_gap"] == 2
    assert r.late_frames()["windower_out_of_order"] == 5 and r.descriptors() == 4
    d = r.to_dict()
    assert d["goal"]["no_lost_frames"] is False and json.dumps(d)


def test_soak_scene_lasts_the_soak_without_simulated_frame_faults(tmp_path):
    import yaml

    from tactile_descriptors_ros.sim.scene import scene_path

    path, seconds, cycle_s = soak_scene(600, "nao", tmp_path)
    assert seconds >= 600
    data = yaml.safe_load(path.read_text())
    assert "dropped_frames" not in data["effects"] and "corrupt_frames" not in data["effects"]
    # the demo whole, over and over: each cycle ends with the large objects that press every cell
    demo = yaml.safe_load(scene_path("demo_nao").read_text())["explorations"]
    cycles = len(data["explorations"]) // len(demo)
    assert cycles >= 2 and data["explorations"] == demo * cycles
    assert cycle_s > 60 and (cycles - 1) * cycle_s < seconds <= cycles * cycle_s


def test_rss_growth_is_measured_after_one_cycle_of_the_scene_when_that_is_longer_than_a_minute():
    # 76 s cycles: the second cycle's work is at the level of the first, the RSS step inside the first is not growth
    s = NodeSamples("window_node", "window_node", 1, t_s=[0, 60, 80, 300, 600], rss_mb=[10, 340, 450, 450, 450],
                    cpu_s=[0, 1, 2, 3, 4])
    r = SoakReport("nao", 700.0, 600.0, 10.0, [s], {}, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 2, 0, {}, cycle_s=76.0)
    d = r.to_dict()
    assert d["warmup_s"] == 76.0 and d["nodes"]["window_node"]["rss_at_warmup_mb"] == 450
    assert d["nodes"]["window_node"]["rss_growth_after_warmup_percent"] == pytest.approx(0.0)
    assert d["goal"]["rss_met"] is True
    # a scene shorter than a minute: the first minute is the warm-up
    short = SoakReport("nao", 700.0, 600.0, 10.0, [s], {}, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 2, 0, {}, cycle_s=20.0)
    assert short.to_dict()["warmup_s"] == 60.0 and short.to_dict()["goal"]["rss_met"] is False


@pytest.mark.ros
def test_bench_soak_command_reports_every_node(tmp_path):
    out = subprocess.run([sys.executable, "-m", "tactile_descriptors_ros.tools.cli", "bench", "--soak", "8",
                          "--soak-sample-s", "1", "--soak-set", "contact_node.frames.serialized=false", "--json"],
                         capture_output=True, text=True, timeout=240)
    assert out.returncode == 0, out.stderr[-2000:]
    d = json.loads(out.stdout)
    # the report says what was set for the soak; the node, once it reported, took it
    assert d["overrides"] == {"contact_node": {"frames.serialized": False}}
    if "contact_node: contact" in d["diagnostics"]:
        assert d["diagnostics"]["contact_node: contact"]["frames_serialized"] == "False"
    # tf_publisher is left out where its tf2_msgs is not installed (not on PyPI), and the soak says so
    has_tf = importlib.util.find_spec("tf2_msgs") is not None
    assert set(d["nodes"]) == {"skin_driver", "window_node", "contact_node", "classifier_node"} | (
        {"tf_publisher"} if has_tf else set())
    assert ("tf_publisher (tf_publisher) left out" in out.stderr) is not has_tf, out.stderr[-2000:]
    for n in d["nodes"].values():
        assert len(n["rss_mb"]) >= 5 and n["rss_end_mb"] > 0 and n["cpu_percent"] is not None
    assert set(d["lost_frames"]) == {"lost_frames", "lost_cell_batches", "bad_frames", "sequence_restart"}
    assert "windower_gap" in d["late_frames"] and d["exit_codes"]
    f = d["frames"]  # 8 s may end before the driver's first frames: the split is consistent either way
    assert f["frames_sent_meanwhile"] + f["never_sent"] >= f["frames_due_at_real_rate"]
    assert f["frames_sent_meanwhile"] <= f["frames_sent"] and d["scene_frames_per_s"] > 0
    # the window node reports its sample buffers with its diagnostics (none yet if it was still starting)
    assert (d["windower_buffer_mb"] is None) == ("window_node: windows" not in d["diagnostics"])
    assert all(len(r) == 1 for r in d["rss_per_minute_mb"].values())
    # every node that reported settled its start-up heap and counts its collector's pauses; a driver its read gaps
    for name, p in d["pauses"].items():
        assert p["gc_settle_ms"] > 0 and p["gc_frozen"] > 10_000 and "gc_collections_g2" in p, (name, p)
    assert all("read_gap_max_ms" in p and "read_gap_max_at_s" in p
               for name, p in d["pauses"].items() if name.endswith("skin_driver"))
    assert isinstance(d["bus_loss_events"], list) and all(e["frames"] > 0 for e in d["bus_loss_events"])
    # the recognition path's CPU is every node's but the contact node's and the TF publisher's, judged against
    # one core
    c = d["cpu"]
    path = sum(n["cpu_percent"] for name, n in d["nodes"].items() if name not in ("contact_node", "tf_publisher"))
    assert c["recognition_path_percent"] == pytest.approx(path) and c["cells"] == 116
    assert d["goal"]["cpu_met"] is (path < 100.0)
    # the driver's simulator runs on a thread the soak finds by the id in the driver's diagnostics, which can
    # come after the last sample of so short a soak (then nothing is reported for it: the known answers of
    # test_the_simulators_thread_is_reported_apart_from_the_drivers_own_cpu cover the split)
    if "skin_driver" in c["simulator_percent"]:
        assert 0.0 < c["simulator_percent"]["skin_driver"] < d["nodes"]["skin_driver"]["cpu_percent"]
    else:
        assert c["recognition_path_ms_per_cell_second_without_simulator"] == \
            c["recognition_path_ms_per_cell_second"]


def test_bench_soak_refuses_a_parameter_of_no_node_before_it_starts():
    out = subprocess.run([sys.executable, "-m", "tactile_descriptors_ros.tools.cli", "bench", "--soak", "8",
                          "--soak-set", "no_such_node.frames.serialized=false"], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 2 and "no node named 'no_such_node'" in out.stderr, out.stderr[-2000:]


def test_frames_are_split_into_never_sent_lost_on_the_bus_and_sent_and_lost():
    """Frames the simulator did not send in time are not losses; the bus's gaps and the messages the
    window node never received are, each counted apart; lost frames are judged only when the
    simulated bus kept up with the real rate."""
    nodes = [NodeSamples("skin_driver", "skin_driver", 1), NodeSamples("window_node", "window_node", 2)]
    diag = {"skin_driver: bus": {"bus_frames": "9000", "bus_lost_frames": "7"},
            "skin_driver: left_hand": {"messages": "60", "lost_frames": "7"},
            "skin_driver: chest": {"messages": "40"},
            "window_node: windows": {"fault_lost_frames": "2", "frames_messages_taken": "97",
                                     "windower_buffer_mb": "82.5"}}
    r = SoakReport("nao", 10.0, 10.0, 1.0, nodes, diag, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 2, 10, {},
                   scene_frames_per_s=1000.0, driver_run_s=10.0, frames_sent_in_run=9000)
    f = r.frames_split()
    assert f["frames_due_at_real_rate"] == 10000 and f["frames_sent_meanwhile"] == 9000 and f["never_sent"] == 1000
    assert f["frames_sent"] == 9000
    assert f["sent_percent_of_real_rate"] == pytest.approx(90.0) and f["machine_kept_up"] is False
    assert f["lost_on_bus"] == 7 and f["messages_sent"] == 100 and f["messages_received"] == 97
    assert f["messages_sent_and_lost"] == 2 and f["frames_sent_and_lost"] == 180  # 90 frames a message
    d = r.to_dict()
    assert d["goal"]["no_lost_frames"] is False and d["goal"]["machine_kept_up"] is False
    assert d["windower_buffer_mb"] == 82.5
    kept_up = SoakReport("nao", 10.0, 10.0, 1.0, nodes, {"skin_driver: bus": {"bus_frames": "9950"}},
                         (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 2, 10, {}, scene_frames_per_s=1000.0, driver_run_s=10.0,
                         frames_sent_in_run=9950)
    assert kept_up.frames_split()["machine_kept_up"] is True and kept_up.to_dict()["goal"]["no_lost_frames"]


def test_body_part_messages_dropped_on_the_way_are_lost_cell_batches():
    """A dropped ``SkinPartFrames`` shows only as gaps in its cells' batch numbers (the window node's
    ``lost_cell_batches``): the soak counts them as lost, in cell batches and in frames, and the goal of no lost
    frames is not met even though no message-level counter moved."""
    nodes = [NodeSamples("skin_driver", "skin_driver", 1), NodeSamples("window_node", "window_node", 2)]
    diag = {"skin_driver: bus": {"bus_frames": "12000", "bus_lost_frames": "0"},
            "skin_driver: left_hand": {"messages": "100", "cell_batches": "800"},
            "skin_driver: chest": {"messages": "100", "cell_batches": "400"},
            "window_node: windows": {"fault_lost_frames": "0", "fault_lost_cell_batches": "6"}}
    r = SoakReport("nao", 10.0, 10.0, 1.0, nodes, diag, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 2, 10, {},
                   scene_frames_per_s=1000.0, driver_run_s=10.0, frames_sent_in_run=12000)
    f = r.frames_split()
    assert f["machine_kept_up"] is True and f["messages_sent_and_lost"] == 0
    assert f["cell_batches_sent"] == 1200 and f["cell_batches_sent_and_lost"] == 6
    assert f["frames_sent_and_lost"] == 60  # 10 frames a cell batch
    d = r.to_dict()
    assert d["lost_frames"]["lost_cell_batches"] == 6 and d["goal"]["no_lost_frames"] is False
    assert "6 of 1200 cell batches (60 frames)" in format_soak(r)


def test_rss_per_minute_takes_the_first_sample_of_every_minute():
    s = NodeSamples("window_node", "window_node", 1, t_s=[0, 30, 61, 90, 120], rss_mb=[10, 20, 30, 40, 50],
                    cpu_s=[0] * 5)
    r = SoakReport("nao", 10.0, 150.0, 1.0, [s], {}, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 2, 10, {})
    assert r.rss_per_minute() == {"window_node": [10, 30, 50]}


def test_the_recognition_paths_cpu_is_judged_under_one_core_and_per_cell_second_of_data_sent():
    """Known answers: over 10 s the driver used 4 s of CPU (40 %), the window node 5 s, the classifier 0.2 s,
    the contact node 3 s and the TF publisher 0.1 s; the recognition path leaves the last two out (92 %, under
    one core; the whole graph 123 %).  The bus sent 80 % of the real rate, so 116 cells sent 0.8 x 10 s of data
    each: the path's 9.2 s of CPU over 928 cell-seconds is 9.91 ms per cell-second (the goal is 1 ms)."""
    from tactile_descriptors_lab.bench.soak import CELL_SECOND_GOAL_MS, GRAPH_CPU_GOAL_PERCENT, format_soak

    def used(name: str, pid: int, cpu_s: float) -> NodeSamples:
        return NodeSamples(name, name, pid, t_s=[0.0, 10.0], rss_mb=[100.0, 100.0], cpu_s=[1.0, 1.0 + cpu_s])

    nodes = [used("skin_driver", 1, 4.0), used("window_node", 2, 5.0), used("classifier_node", 3, 0.2),
             used("contact_node", 4, 3.0), used("tf_publisher", 5, 0.1)]
    r = SoakReport("nao", 10.0, 10.0, 1.0, nodes, {}, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 2, 0, {},
                   scene_frames_per_s=1000.0, driver_run_s=10.0, frames_sent_in_run=8000, cells=116)
    d = r.to_dict()
    c = d["cpu"]
    assert c["graph_percent"] == pytest.approx(123.0) and c["recognition_path_percent"] == pytest.approx(92.0)
    assert c["data_share_of_real_rate"] == pytest.approx(0.8)
    assert c["ms_per_cell_second"]["skin_driver"] == pytest.approx(4000.0 / 928.0)
    assert c["recognition_path_ms_per_cell_second"] == pytest.approx(9200.0 / 928.0)
    assert d["goal"]["recognition_path_cpu_max_percent"] == GRAPH_CPU_GOAL_PERCENT
    assert d["goal"]["cpu_met"] is True and d["goal"]["cell_second_met"] is False
    assert d["goal"]["ms_per_cell_second_max"] == CELL_SECOND_GOAL_MS
    text = format_soak(r)
    assert "92.0 %, met (the whole graph 123.0 %)" in text and "9.91, NOT met" in text, text
    # a window node working 1.5 cores puts the path over one core
    nodes[1] = used("window_node", 2, 15.0)
    over = SoakReport("nao", 10.0, 10.0, 1.0, nodes, {}, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 2, 0, {},
                      scene_frames_per_s=1000.0, driver_run_s=10.0, frames_sent_in_run=10000, cells=116)
    assert over.to_dict()["goal"]["cpu_met"] is False
    # without CPU samples or cells nothing is judged
    bare = SoakReport("nao", 10.0, 10.0, 1.0, [NodeSamples("window_node", "window_node", 2)], {},
                      (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 2, 0, {})
    assert bare.to_dict()["goal"]["cpu_met"] is None and bare.to_dict()["goal"]["cell_second_met"] is None


def test_the_simulators_thread_is_reported_apart_from_the_drivers_own_cpu():
    """Known answers: the driver's process used 4 s of CPU over 10 s, 1.5 s of it on its simulator's thread
    (unknown at the first sample, when the process had just started); with the window node's 5 s the path is
    9 s, 7.5 s without the simulator: 7500 / 1160 ms per cell-second.  The goals stay judged with it."""
    from tactile_descriptors_lab.bench.soak import format_soak

    driver = NodeSamples("skin_driver", "skin_driver", 1, t_s=[0.0, 5.0, 10.0], rss_mb=[100.0] * 3,
                         cpu_s=[1.0, 3.0, 5.0], simulator_cpu_s=[None, 0.7, 1.5])
    window = NodeSamples("window_node", "window_node", 2, t_s=[0.0, 10.0], rss_mb=[100.0] * 2, cpu_s=[0.0, 5.0])
    r = SoakReport("nao", 10.0, 10.0, 1.0, [driver, window], {}, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 2, 0, {},
                   scene_frames_per_s=1000.0, driver_run_s=10.0, frames_sent_in_run=10000, cells=116)
    c = r.to_dict()["cpu"]
    assert c["simulator_percent"] == {"skin_driver": pytest.approx(15.0)}
    assert c["simulator_ms_per_cell_second"]["skin_driver"] == pytest.approx(1500.0 / 1160.0)
    assert c["recognition_path_ms_per_cell_second"] == pytest.approx(9000.0 / 1160.0)
    assert c["recognition_path_ms_per_cell_second_without_simulator"] == pytest.approx(7500.0 / 1160.0)
    assert r.to_dict()["goal"]["cell_second_met"] is False
    assert "the recognition path without it 6.47" in format_soak(r)
    # a driver whose simulator thread was never seen (a hardware bus) reports none
    driver.simulator_cpu_s = [None, None, None]
    c = r.to_dict()["cpu"]
    assert c["simulator_percent"] == {} and c["recognition_path_ms_per_cell_second_without_simulator"] == \
        pytest.approx(c["recognition_path_ms_per_cell_second"])


def test_when_frames_were_lost_and_each_nodes_pauses_are_reported():
    """The times the driver's bus lost frames (so that a loss can be matched with its cause) and, per node,
    the collector's pauses (its ``process`` status) and a driver's longest gap between reads."""
    nodes = [NodeSamples("skin_driver", "skin_driver", 1), NodeSamples("window_node", "window_node", 2)]
    diag = {"skin_driver: bus": {"bus_frames": "12000", "bus_lost_frames": "300", "read_gap_max_ms": "1058.5",
                                 "read_gap_max_at_s": "437.2", "read_gaps_long": "6", "transport": "simulated"},
            "skin_driver: process": {"gc_collections_g2": "1", "gc_max_ms_g2": "90.2", "gc_frozen": "0"},
            "window_node: process": {"gc_collections_g2": "0", "gc_max_ms_g2": "0", "gc_settle_ms": "70.1",
                                     "gc_frozen": "161157"},
            "window_node: windows": {"fault_lost_frames": "0"}}
    r = SoakReport("nao", 10.0, 10.0, 1.0, nodes, diag, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 2, 10, {},
                   scene_frames_per_s=1000.0, driver_run_s=10.0, frames_sent_in_run=12000,
                   loss_events=[(284.94, "skin_driver: bus", 100), (436.9, "skin_driver: bus", 200)])
    d = r.to_dict()
    assert d["bus_loss_events"] == [{"t_s": 284.9, "status": "skin_driver: bus", "frames": 100},
                                    {"t_s": 436.9, "status": "skin_driver: bus", "frames": 200}]
    assert d["pauses"] == {"skin_driver": {"read_gap_max_ms": 1058.5, "read_gap_max_at_s": 437.2, "read_gaps_long": 6.0,
                                           "gc_collections_g2": 1.0, "gc_max_ms_g2": 90.2, "gc_frozen": 0.0},
                           "window_node": {"gc_collections_g2": 0.0, "gc_max_ms_g2": 0.0, "gc_settle_ms": 70.1,
                                           "gc_frozen": 161157.0}}
    text = format_soak(r)
    assert "frames lost on the bus at: 285 s (100), 437 s (200)" in text
    assert "read_gap_max_ms 1058.5, read_gap_max_at_s 437.2" in text and "gc_settle_ms 70.1" in text
