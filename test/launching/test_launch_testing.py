"""The simulated Shadow Hand graph as a ``launch_testing`` integration test, the ROS 2 convention.

``generate_test_description()`` includes the installed
``shadow_hand.launch.py`` (found through the ament index, as ``ros2 launch``
finds it) on the simulated demo scene with a fresh model file, and
``ReadyToTest`` starts the active tests at once: they wait for the first
``Prediction`` (no model yet), teach its exploration with a ``Label`` and wait
for the classifier's "learned" line in the nodes' output.  After launch_testing
shuts the graph down (SIGINT to every node), the post-shutdown tests check the
exit codes with ``launch_testing.asserts.assertExitCodes`` and that the
classifier left its model file.

pytest runs it through launch_testing's pytest plugin (registered by the
``launch_testing`` package's ``pytest11`` entry point, so ``make test`` runs it
with the rest; ``launch_test test/launching/test_launch_testing.py`` runs it
alone).  Skipped with the reason where launch_testing or the ros2 launch system
is not installed (``make setup`` installs them from ``../shared/ros2-cli``).
"""

from __future__ import annotations

import re
import shutil
import tempfile
import time
import unittest
from pathlib import Path

import pytest

try:
    import launch_testing
    import launch_testing.actions
    import launch_testing.asserts
    from ament_index_python.packages import PackageNotFoundError, get_package_share_directory
    from launch.launch_description_sources import PythonLaunchDescriptionSource

    import launch
except ImportError as exc:  # pragma: no cover - depends on the set-up
    pytest.skip(f"launch_testing / the ros2 launch system is not installed ({exc}); make setup installs it from "
                "../shared/ros2-cli", allow_module_level=True)

PKG = "tactile_descriptors_ros"
SCENE = "demo_shadow_hand"
#: Generous bounds for a loaded 2-core machine: they stop a hung test, they measure nothing.
FIRST_PREDICTION_S = 240.0
EVENT_S = 60.0


def _launch_file() -> Path:
    try:
        share = Path(get_package_share_directory(PKG))
    except PackageNotFoundError:  # pragma: no cover - depends on the set-up
        pytest.skip(f"{PKG} is not in the ament index (AMENT_PREFIX_PATH): run make setup")
    return share / "launch" / "shadow_hand.launch.py"


@pytest.mark.launch_test
@pytest.mark.ros
@pytest.mark.ros2cli
@pytest.mark.slow
@pytest.mark.timeout(900)
def generate_test_description():
    """The Shadow Hand graph on the simulated demo scene, with a model file of its own; tests start at once."""
    model_path = Path(tempfile.mkdtemp(prefix="tactile_launch_test_")) / "model.json"
    graph = launch.actions.IncludeLaunchDescription(
        PythonLaunchDescriptionSource(str(_launch_file())),
        launch_arguments={"sim": SCENE, "model_path": str(model_path)}.items())
    return launch.LaunchDescription([graph, launch_testing.actions.ReadyToTest()]), {"model_path": model_path}


class TestFirstPrediction(unittest.TestCase):
    """Active tests, while the graph runs."""

    @classmethod
    def setUpClass(cls):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import QoSProfile, ReliabilityPolicy

        from tactile_descriptors_msgs.msg import Label, Prediction

        cls.context = rclpy.Context()
        rclpy.init(context=cls.context)
        cls.node = rclpy.create_node("launch_test_probe", context=cls.context)
        qos = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
        cls.predictions = []
        cls.node.create_subscription(Prediction, "/tactile/prediction", cls.predictions.append, qos)
        cls.labels = cls.node.create_publisher(Label, "/tactile/label", qos)
        cls.executor = SingleThreadedExecutor(context=cls.context)
        cls.executor.add_node(cls.node)

    @classmethod
    def tearDownClass(cls):
        import rclpy

        cls.executor.shutdown(timeout_sec=1.0)
        cls.node.destroy_node()
        rclpy.try_shutdown(context=cls.context)

    def _spin_until(self, done, timeout_s: float) -> bool:
        deadline = time.monotonic() + timeout_s
        while not done() and time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.1)
        return done()

    def test_first_prediction_then_a_label_teaches_the_classifier(self, proc_output, model_path):
        from tactile_descriptors_msgs.msg import Label

        self.assertTrue(self._spin_until(lambda: self.predictions, FIRST_PREDICTION_S),
                        f"no Prediction within {FIRST_PREDICTION_S:.0f} s")
        first = self.predictions[0]
        self.assertGreaterEqual(first.exploration_id, 1)  # an exploration window of the scene
        self.assertFalse(first.has_model)                 # a fresh model file: nothing learned yet
        self.assertEqual((first.class_name, list(first.class_names), first.updates), ("", [], 0))
        # the label reaches the classifier once its subscription is matched (reliable: then it is delivered)
        self.assertTrue(self._spin_until(lambda: self.labels.get_subscription_count() >= 1, EVENT_S),
                        "the classifier's label subscription was not discovered")
        self.labels.publish(Label(exploration_id=first.exploration_id, class_name="cork"))
        # the classifier's log line (stderr), once the update is durable in the model's journal
        proc_output.assertWaitFor(re.compile(rf"learned exploration {first.exploration_id}: 'cork' \(new class\), "
                                             r"loss [\d.]+, 1 classes, saved"), timeout=EVENT_S, stream="stderr")


@launch_testing.post_shutdown_test()
class TestShutdown(unittest.TestCase):
    """After launch_testing stopped the graph."""

    def test_every_node_exited_cleanly(self, proc_info):
        # SIGINT: drivers, window node, classifier, contact node and tf_publisher each end with exit code 0
        # (none escalated to SIGTERM)
        launch_testing.asserts.assertExitCodes(proc_info)
        self.assertEqual(sorted(Path(info.cmd[0]).name for info in proc_info),
                         ["biotac_driver", "classifier_node", "contact_node", "tf_publisher", "window_node"])

    def test_the_classifier_kept_what_it_learned(self, model_path):
        path = Path(model_path)
        self.assertTrue(path.is_file(), f"{path} not written")
        self.assertIn('"cork"', path.read_text())
        self.assertFalse(Path(f"{path}.journal").exists(), "the journal was not compacted at shutdown")
        shutil.rmtree(path.parent)
