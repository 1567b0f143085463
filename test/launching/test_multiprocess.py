"""ONE multi-process test: the in-repo launcher starts the simulated Shadow Hand graph over DDS on
localhost; this process checks what arrives on the prediction topic and feeds labels back."""

from __future__ import annotations

import time

import pytest

pytestmark = [pytest.mark.ros, pytest.mark.slow]


def test_launcher_runs_the_simulated_graph_and_predictions_learn(tmp_path):
    import random

    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from tactile_descriptors_msgs.msg import Prediction
    from tactile_descriptors_msgs.srv import LearnLabel
    from tactile_descriptors_ros.launching.graph import build_graph
    from tactile_descriptors_ros.launching.processes import GraphProcesses, localhost_environment

    specs = build_graph("shadow_hand", sim_scene="demo_shadow_hand", model_path=str(tmp_path / "model.json"),
                        overrides={"biotac_driver": {"stamp_source": "device", "sim.speed": 2.0}})
    domain = random.randint(1, 100)  # this test's own domain: children and the test node
    env = localhost_environment()
    env["ROS_DOMAIN_ID"] = str(domain)
    procs = GraphProcesses(specs, env=env, output=None)
    ros_context = rclpy.Context()
    rclpy.init(context=ros_context, domain_id=domain)
    node = rclpy.create_node("test_io", context=ros_context)
    qos = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
    preds: list = []
    node.create_subscription(Prediction, "tactile/prediction", preds.append, qos)
    client = node.create_client(LearnLabel, "/classifier_node/label")
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(node)
    procs.start()
    try:
        deadline = time.monotonic() + 90.0
        while time.monotonic() < deadline and not preds and not procs.exited():
            ex.spin_once(timeout_sec=0.1)
        assert not procs.exited(), {n.spec.name: n.lines[-10:] for n in procs.exited()}
        assert preds, f"no prediction within 90 s: {[n.lines[-5:] for n in procs.nodes]}"
        first = preds[0]
        assert first.exploration_id >= 1 and not first.has_model and first.class_name == ""
        assert list(first.class_names) == [] and len(first.scores) == 0
        t_end = first.window_end.sec + first.window_end.nanosec * 1e-9
        assert 1.0 < t_end < 75.0  # simulated sensor time (stamp_source device): inside the scene
        # ~/label answers once the label is learned and saved: the test waits for that event, then for a
        # prediction made with the model that learned it (one already in flight may still arrive first)
        assert client.wait_for_service(timeout_sec=90.0), "no /classifier_node/label service"
        answer = client.call_async(LearnLabel.Request(exploration_id=first.exploration_id, class_name="steel"))
        while time.monotonic() < deadline and not answer.done() and not procs.exited():
            ex.spin_once(timeout_sec=0.1)
        assert answer.done(), f"the label was not answered: {[n.lines[-5:] for n in procs.nodes]}"
        result = answer.result()
        assert (result.success, result.saved, result.exploration_id, result.model_version) == \
            (True, True, first.exploration_id, 1), result
        while time.monotonic() < deadline and not any(p.updates >= 1 for p in preds) and not procs.exited():
            ex.spin_once(timeout_sec=0.1)
        second = next((p for p in preds if p.updates >= 1), None)
        assert second is not None, "no prediction with the learned model"
        assert second.exploration_id > first.exploration_id
        assert second.has_model and second.class_name == "steel" and list(second.class_names) == ["steel"]
        assert second.updates == 1 and len(second.scores) == 1
    finally:
        codes = procs.stop()
        node.destroy_node()
        rclpy.try_shutdown(context=ros_context)
    # SIGINT stops every node cleanly
    assert all(c in (0, -2, 130) for c in codes.values()), {n.spec.name: (codes[n.spec.name], n.lines[-25:])
                                                            for n in procs.nodes if codes[n.spec.name] not in (0, -2, 130)}
    assert (tmp_path / "model.json").is_file()  # the classifier saved its model after the update
