"""Every command block of the README and docs/ runs as written, so the docs cannot drift from the code.

The blocks run through :mod:`doc_blocks` (``test/doc_blocks.py``); the lab's
pages (``lab/README.md``, ``lab/docs/``) are run by the lab's own test.
"""

from __future__ import annotations

import pytest
from doc_blocks import REPO, blocks, run_page, untagged_command_blocks

PAGES = ["README.md", *sorted(str(p.relative_to(REPO)) for p in (REPO / "docs").glob("*.md"))]

#: (page, first line of the block) -> why it does not run here.
SKIP: dict[tuple[str, str], str] = {
    ("README.md", "make demo   # sets everything up, then a simulated Shadow Hand through the live node graph"):
        "`make test` is this test suite (it would run itself); the demo's graph is what "
        "test/launching/test_ros2_launch.py launches",
    ("README.md", "mkdir -p ~/ws/src && cd ~/ws/src && git clone <this repository> tactile_descriptors_ros"):
        "needs rosdep and a clone URL; test/packaging/test_colcon.py builds the same two packages "
        "with the same colcon command and launches from install/",
    ("README.md", 'rviz2 -d "$(ros2 pkg prefix tactile_descriptors_ros)/share/tactile_descriptors_ros/config/rviz/'
                  'shadow_hand.rviz"'):
        "rviz2 is not installable from PyPI; test/core/test_urdf_rviz.py checks that file (topics, QoS, fixed "
        "frame) and test/packaging/test_ament_index.py that the share directory holds it",
    ("docs/view.md", "tactile bench --view-overhead --rounds 2 --seconds 30"):
        "four runs of the NAO's contact node at full rate, minutes; lab/test/bench/test_view_overhead.py runs "
        "the same command with one short round",
    ("docs/simulator.md", "tactile fit-textures ../shared/data/biotac_slide_20_50 -o texture_models   "
                          "# fit the texture models (default ./texture_models)"):
        "a lab verb that fits all 20 materials of the real recordings (minutes) and rewrites the shipped models; "
        "lab/test/textures/test_fitting.py fits and checks them",
    ("docs/simulator.md", "tactile demo nao"):
        "two live NAO graphs of minutes each; lab/test/test_protocols.py scores the same two scenes with the "
        "classifier node's learner offline, test/launching/test_ros2_launch.py launches the demo's graph",
}


def test_command_blocks_are_tagged():
    untagged = untagged_command_blocks(PAGES)
    assert not untagged, f"tag these blocks `bash` (commands) or `text` (a synopsis): {untagged}"


def test_skip_list_names_existing_blocks():
    present = {(b.page, b.first) for page in PAGES for b in blocks(page)}
    assert set(SKIP) <= present, f"stale SKIP entries: {set(SKIP) - present}"


@pytest.mark.ros
@pytest.mark.ros2cli
@pytest.mark.slow
@pytest.mark.timeout(1800)
@pytest.mark.parametrize("page", PAGES)
def test_page_commands_run(page, tmp_path):
    run_page(page, SKIP, tmp_path)
