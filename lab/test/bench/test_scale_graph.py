"""``tactile bench --scale-graph``: a synthetic skin through drivers and one window node per body part."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import pytest

from tactile_descriptors_lab.bench.scale_graph import PartResult, ProcessLoad, _part_timing, scale_graph_specs
from tactile_descriptors_ros.core.robot import load_robot
from tactile_descriptors_ros.errors import ConfigError
from tactile_descriptors_ros.sim.scene import load_scene
from tactile_descriptors_ros.sim.synthetic import WINDOW_HOP_S, scale_robot_files, split_cells


def test_cells_are_split_into_body_parts_whose_sizes_differ_by_at_most_one():
    runs = split_cells(10_001, 20)
    assert [i for r in runs for i in r] == list(range(1, 10_002))
    assert {len(r) for r in runs} == {500, 501}
    with pytest.raises(ConfigError):
        split_cells(3, 4)


def test_the_robot_launches_one_driver_and_one_window_node_per_body_part(tmp_path):
    path = scale_robot_files(90, 3, tmp_path)
    robot = load_robot(path)
    assert robot.n_cells == 90 and [len(p.cells) for p in robot.body_parts] == [30, 30, 30]
    assert robot.window.mode == "fixed" and (robot.window.length_s, robot.window.hop_s) == (2.0, 0.5)
    specs = scale_graph_specs(path)
    drivers = [s for s in specs if s.executable == "skin_driver"]
    windows = [s for s in specs if s.executable == "window_node"]
    assert len(specs) == 6 and len(drivers) == len(windows) == 3
    for part, drv, win in zip(robot.body_parts, drivers, windows):
        assert drv.parameters["body_parts"] == win.parameters["body_parts"] == [part.name]
        assert drv.parameters["transport"] == "simulated" and drv.parameters["sim.loop"] is True
        scene = load_scene(drv.parameters["sim.scene"])
        # each driver's bus carries its own cells only, under the robot's name (the driver checks it)
        assert scene.robot.name == robot.name
        assert [c.id for p in scene.robot.body_parts for c in p.cells] == [c.id for c in part.cells]
    assert {w.parameters["exploration_id_stride"] for w in windows} == {3}


def test_one_driver_serves_every_body_part_on_request(tmp_path):
    specs = scale_graph_specs(scale_robot_files(40, 2, tmp_path, one_driver=True))
    drivers = [s for s in specs if s.executable == "skin_driver"]
    assert len(drivers) == 1 and drivers[0].parameters["body_parts"] == ["part_0", "part_1"]
    assert sum(s.executable == "window_node" for s in specs) == 2


def _rows(n: int, lag_growth_s: float) -> list[tuple[float, int, int]]:
    """Descriptors every hop whose lag grows linearly by ``lag_growth_s`` over the run."""
    out = []
    for k in range(n):
        arrival = 10.0 + k * WINDOW_HOP_S
        lag = 0.2 + lag_growth_s * k / (n - 1)
        out.append((arrival, int((arrival - lag) * 1e9), 5))
    return out


def test_a_steady_lag_is_real_time_and_a_growing_lag_is_not():
    n, rtf, growth = _part_timing(_rows(40, 0.0), 10.0, 30.0)
    assert n == 40 and rtf == pytest.approx(1.0, abs=1e-3) and growth == pytest.approx(0.0, abs=1e-6)
    n, rtf, growth = _part_timing(_rows(40, 2.0), 10.0, 30.0)
    assert rtf < 0.9 and growth > 1.5


def _part(**changes) -> PartResult:
    kept = dict(name="part_0", cells=10, lost={"lost_frames": 0}, late={"windower_gap": 0}, bus_lost_frames=0,
                driver_realtime_factor=1.0, windows=20, windows_expected=20.0, realtime_factor=1.0, lag_growth_s=0.0)
    kept.update(changes)
    return PartResult(**kept)


def test_a_body_part_keeps_up_only_without_lost_frames_missing_windows_or_a_growing_lag():
    assert _part().kept_up
    assert not _part(lost={"lost_frames": 1}).kept_up
    assert not _part(late={"windower_gap": 1}).kept_up
    assert not _part(bus_lost_frames=1).kept_up
    assert not _part(windows=18).kept_up
    assert not _part(lag_growth_s=WINDOW_HOP_S).kept_up
    assert not _part(driver_realtime_factor=0.9).kept_up
    assert _part(windows=19).kept_up  # a window on either side of the measurement's edges


def test_the_graph_is_stopped_when_the_machine_runs_short_of_memory(monkeypatch):
    import os
    from types import SimpleNamespace

    from tactile_descriptors_lab.bench import scale_graph

    me = SimpleNamespace(nodes=[SimpleNamespace(process=SimpleNamespace(pid=os.getpid()))])
    monkeypatch.setattr(scale_graph, "MEMORY_FLOOR_GB", 0.0)
    assert scale_graph._memory_short(me, 0.0) is None
    monkeypatch.setattr(scale_graph, "MEMORY_FLOOR_GB", 1e9)  # more than any machine has
    why = scale_graph._memory_short(me, 0.0)
    assert why.startswith("stopped after") and "1 processes held" in why
    report = scale_graph.ScaleGraphReport(4, [_part()], [], 1.0, 1.0, ("paper",), False, (0, 0, 0), (0, 0, 0), 2,
                                          stopped=why)
    assert not report.kept_up and report.targets()["skin_4_graph"]["met"] is False
    assert report.to_dict()["stopped"] == why


def test_a_process_that_fell_behind_is_charged_for_the_data_it_handled_not_the_wall_time():
    p = ProcessLoad("skin_driver_part_0", "skin_driver", 1, cells=100, cpu_percent=50.0, data_realtime_factor=0.5)
    assert p.cpu_ms_per_cell_s == pytest.approx(5.0)  # half a core for 100 cells
    assert p.cpu_ms_per_cell_data_s == pytest.approx(10.0)  # ... handling half of their data
    assert ProcessLoad("w", "window_node", 2, cells=100, cpu_percent=50.0).cpu_ms_per_cell_data_s is None


@pytest.mark.ros
@pytest.mark.slow
def test_bench_scale_graph_runs_a_small_skin_in_real_time_without_lost_frames():
    cells, parts, seconds = 40, 2, 6
    out = subprocess.run([sys.executable, "-m", "tactile_descriptors_ros.tools.cli", "bench", "--scale-graph",
                          "--cells", str(cells), "--parts", str(parts), "--seconds", str(seconds), "--json"],
                         capture_output=True, text=True, timeout=280)
    assert out.returncode == 0, out.stderr[-3000:]
    d = json.loads(out.stdout)
    assert set(d["processes"]) == {"skin_driver_part_0", "skin_driver_part_1", "window_node_part_0",
                                   "window_node_part_1"}
    for p in d["processes"].values():
        assert p["cpu_percent"] > 0 and p["rss_mb"] > 0 and p["cells"] == cells // parts
    for name, p in d["parts"].items():
        assert p["lost_frames"] == 0, (name, p)
        assert "lost_cell_batches" in p["lost"]  # a dropped body-part message: its cells' batches, counted
        assert p["messages_sent"] > 0 and p["messages_received"] > 0
        assert p["windows"] >= math.floor(p["windows_expected"]) - 1, (name, p)
        assert p["cells_in_contact"] == cells // parts  # every cell touches: the descriptor's full cost
    target = d["targets"][f"skin_{cells}_graph"]
    assert target["lost_frames"] == 0 and target["met"] is True, d["parts"]


@pytest.mark.ros
@pytest.mark.slow
def test_a_graph_without_descriptors_when_the_warm_up_ends_is_measured_anyway():
    out = subprocess.run([sys.executable, "-m", "tactile_descriptors_ros.tools.cli", "bench", "--scale-graph",
                          "--cells", "4", "--parts", "1", "--seconds", "2", "--settle-s", "0", "--warm-up-s", "0.1",
                          "--json"], capture_output=True, text=True, timeout=280)
    assert out.returncode == 0, out.stderr[-3000:]
    d = json.loads(out.stdout)
    assert d["silent_at_start"] == ["part_0"]  # no window can close 0.1 s after start
    assert all(p["cpu_percent"] is not None for p in d["processes"].values())
