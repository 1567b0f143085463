"""tactile view in headless Chromium against the running simulated graph: what the page shows, asserted.

The simulated touch scene runs through ``tactile launch``; ``tactile view`` serves the page; the test labels
the first exploration (as an experimenter would) and waits until the page shows the cells in contact coloured
by force and a predicted class with its confidence, then takes a screenshot.  With
``TACTILE_VIEW_SCREENSHOTS=DIR`` the screenshots are written there (``docs/figures`` holds the shipped ones:
``TACTILE_VIEW_SCREENSHOTS=docs/figures pytest test/view/test_browser.py``).
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from chromium import CHROMIUM, Chromium
from graph import launched

IN_CI = os.environ.get("CI", "").lower() in {"1", "true", "yes"}
pytestmark = [pytest.mark.ros, pytest.mark.slow,
              pytest.mark.skipif(CHROMIUM is None and not IN_CI,
                                 reason="no chromium: `make test` installs Debian's chromium with apt-get as root; "
                                        "here it could not")]


@pytest.fixture(autouse=True)
def _chromium_installed():
    """In CI the set-up installs chromium (``make browser``): its absence is a failure, not a skip."""
    if CHROMIUM is None:
        pytest.fail("no chromium in CI: `make browser` (run by `make test`) installs Debian's chromium with apt-get")

CONTACT_JS = """(() => {
  const parts = [...document.querySelectorAll('.part[data-in-contact="true"]')];
  const hot = parts.flatMap(p => [...p.querySelectorAll('circle[data-force-n]')])
                   .filter(c => c.dataset.forceN !== '' && parseFloat(c.dataset.forceN) >= 0.2);
  return parts.length && hot.length ? {parts: parts.map(p => p.dataset.part), fill: hot[0].getAttribute('fill'),
                                       force: parseFloat(hot[0].dataset.forceN)} : null;
})()"""


@pytest.mark.timeout(900)
@pytest.mark.parametrize("robot", ["shadow_hand", "nao"])
def test_page_shows_contact_coloured_and_the_predicted_class(robot, ros_context, tmp_path):
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    from tactile_descriptors_msgs.msg import Label, Prediction
    from tactile_descriptors_ros.core.colormap import force_colours
    from tactile_descriptors_ros.core.robot import load_robot
    from tactile_descriptors_ros.sim.scene import load_scene

    scene = load_scene(f"touch_{robot}")
    classes = {e.label for e in scene.explorations}
    node = rclpy.create_node("experimenter", context=ros_context)
    predictions = []
    node.create_subscription(Prediction, "tactile/prediction", predictions.append, 50)
    labels = node.create_publisher(Label, "tactile/label", 10)
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(node)
    view = None
    browser = None
    with launched(robot, f"touch_{robot}", tmp_path / "graph.log", "--model-path", str(tmp_path / "model.json")):
        try:
            view = subprocess.Popen([sys.executable, "-m", "tactile_descriptors_ros.tools.cli", "view", "--port", "0"],
                                    stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
            url = re.search(r"http://\S+/", view.stdout.readline()).group(0)
            browser = Chromium(tmp_path / "profile")
            browser.goto(url)
            assert browser.wait_for("document.querySelectorAll('.part').length", 240) == \
                len(load_robot(robot).body_parts), (tmp_path / "graph.log").read_text()[-3000:]
            assert browser.evaluate("document.getElementById('robot').textContent") == robot
            # the experimenter labels the first exploration once it is predicted (there is no model before)
            deadline = time.monotonic() + 300
            while time.monotonic() < deadline and not predictions:
                ex.spin_once(timeout_sec=0.1)
            assert predictions, (tmp_path / "graph.log").read_text()[-3000:]
            first = scene.explorations[0].label
            while time.monotonic() < deadline and not any(p.has_model for p in predictions):
                if node.count_subscribers("tactile/label"):
                    labels.publish(Label(exploration_id=int(predictions[0].exploration_id), class_name=first))
                for _ in range(10):
                    ex.spin_once(timeout_sec=0.1)
            predicted = browser.wait_for(
                "document.getElementById('prediction').dataset.hasModel === 'true' && "
                "document.getElementById('prediction-class').textContent", 300)
            assert predicted in classes
            assert re.fullmatch(r"confidence \d+ %", browser.evaluate(
                "document.getElementById('prediction-confidence').textContent"))
            assert browser.wait_for(f"[...document.querySelectorAll('#history tbody tr td:nth-child(4)')]"
                                    f".some(td => td.textContent === '{first}')", 60)
            hot = browser.wait_for(CONTACT_JS, 300)
            shot = browser.screenshot(tmp_path / f"view_{robot}.png")
            assert hot, (tmp_path / "graph.log").read_text()[-3000:]
            # the colour is the force's on the robot's fixed scale (viridis), as the markers and images have it
            scale = load_robot(robot).view.force_max_n
            r, g, b = force_colours([hot["force"]], scale)[0]
            assert hot["fill"] == f"rgb({r},{g},{b})"
            assert browser.evaluate("document.getElementById('status').dataset.state") == "live"
            assert shot.read_bytes()[:4] == b"\x89PNG"
            out = os.environ.get("TACTILE_VIEW_SCREENSHOTS")
            if out:
                shutil.copy(shot, Path(out) / shot.name)
        finally:
            if browser is not None:
                browser.close()
            if view is not None:
                os.killpg(view.pid, signal.SIGINT)
                _, err = view.communicate(timeout=60)
                assert view.returncode == 0 and "Traceback" not in err, err
            node.destroy_node()
