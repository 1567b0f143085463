"""The looped skin CAN source: one simulated scene played over and over as one endless recording."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from tactile_descriptors_ros.codecs.skin import Modality
from tactile_descriptors_ros.codecs.skin_can import SkinCanDecoder
from tactile_descriptors_ros.errors import SceneError
from tactile_descriptors_ros.sim.scene import load_scene
from tactile_descriptors_ros.sim.sources import LoopedSkinCanSource, SkinCanSource
from tactile_descriptors_ros.sim.synthetic import scale_robot_files


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    robot = scale_robot_files(6, 2, tmp_path_factory.mktemp("loop"))
    return load_scene(str(robot).replace(".yaml", "_part_0.scene.yaml"))


def test_the_first_lap_is_the_scene_frame_for_frame(scene):
    looped = LoopedSkinCanSource(scene, laps=1)
    looped.open()
    plain = SkinCanSource(scene)
    plain.open()
    a, b = looped.recv_batch(10**7, 0.0), plain.recv_batch(10**7, 0.0)
    assert len(a) == len(b) > 0
    assert (a == b).all()
    assert looped.finished


def test_laps_join_without_a_sequence_gap_or_a_jump_in_the_sample_grid(scene):
    src = LoopedSkinCanSource(scene, laps=3)
    src.open()
    frames = src.recv_batch(10**7, 0.0)
    dec = SkinCanDecoder(known_cell_ids=[c.id for p in scene.robot.body_parts for c in p.cells])
    batch = dec.decode_frames(frames)
    stats = dec.stats.as_dict()
    assert stats["frames"] == len(frames) == 3 * len(frames) // 3
    assert stats["lost_frames"] == stats["sequence_gaps"] == stats["duplicates"] == stats["out_of_order"] == 0
    period_ns = {Modality.ACCEL: 1_000_000, Modality.FORCE: 4_000_000}
    for cell in {int(c) for c in batch.cell_id}:
        for mod, period in period_ns.items():
            t = batch.stamp_ns[(batch.cell_id == cell) & (batch.modality == int(mod))]
            assert t.size == 3 * round(scene.duration_s * 1e9 / period)
            steps = np.diff(t)
            assert steps.min() >= period - 1 and steps.max() <= period + 1  # float seconds on the wire


def test_later_laps_are_the_first_shifted_in_time_and_numbered_on(scene):
    src = LoopedSkinCanSource(scene, laps=2)
    src.open()
    frames = src.recv_batch(10**7, 0.0)
    first, second = frames[:len(frames) // 2], frames[len(frames) // 2:]
    assert (second["arbitration_id"] == first["arbitration_id"]).all()
    assert (second["data"][:, 1:] == first["data"][:, 1:]).all()
    assert np.allclose(second["timestamp"] - first["timestamp"], scene.duration_s, atol=1e-9)
    assert not (second["data"][:, 0] == first["data"][:, 0]).all()


def test_a_paced_loop_hands_out_only_due_frames(scene):
    now = [0.0]
    src = LoopedSkinCanSource(scene, speed=1.0, clock=lambda: now[0])
    src.open()
    now[0] = 0.5
    due = src.recv_batch(10**7, 0.0)
    assert len(due) and due["timestamp"].max() <= 0.5 + scene.start_ns * 1e-9
    now[0] = 3 * scene.duration_s + 0.5  # past the first laps: the endless loop goes on
    later = src.recv_batch(10**7, 0.0)
    assert later["timestamp"].max() > 3 * scene.duration_s and not src.finished


def test_scenes_with_bus_faults_or_a_broken_grid_are_refused(scene, tmp_path):
    data = yaml.safe_load(open(scene.source))
    data["effects"]["dropped_frames"] = {"probability": 0.001}
    faulty = tmp_path / "faulty.yaml"
    faulty.write_text(yaml.safe_dump(data))
    with pytest.raises(SceneError, match="dropped_frames"):
        LoopedSkinCanSource(load_scene(faulty))
    data = yaml.safe_load(open(scene.source))
    data["scene"]["lead_in_s"] = 0.0515  # a lap of 2.0015 s: not a whole number of 250 Hz periods
    broken = tmp_path / "broken.yaml"
    broken.write_text(yaml.safe_dump(data))
    with pytest.raises(SceneError, match="whole number"):
        LoopedSkinCanSource(load_scene(broken)).open()
