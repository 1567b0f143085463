"""Test configuration: keep DDS on this machine, isolate each run, share fixtures.

Set before anything imports rclpy: discovery stays on localhost
(``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``; Kilted ignores
``ROS_LOCALHOST_ONLY``) and a random domain id keeps concurrent runs apart.
"""

from __future__ import annotations

import os
import random
from pathlib import Path

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.setdefault("ROS_DOMAIN_ID", str(random.randint(1, 100)))
_REPO = Path(__file__).resolve().parent
os.environ.setdefault("ROS_LOG_DIR", str(_REPO / "build" / "ros_log"))
os.environ.setdefault("MPLBACKEND", "Agg")
# A process a test starts that dies of a fatal signal (a segmentation fault in a DDS library) prints the
# Python stack of each of its threads on stderr, which the failing test shows.
os.environ.setdefault("PYTHONFAULTHANDLER", "1")
# The wheels set no ament prefix: the venv is the prefix this package is indexed in
# (make setup), as a sourced .venv/setup.bash would say.
import sys  # noqa: E402

if sys.prefix not in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep):
    os.environ["AMENT_PREFIX_PATH"] = os.pathsep.join(
        p for p in (sys.prefix, os.environ.get("AMENT_PREFIX_PATH", "")) if p)

import signal  # noqa: E402

import pytest  # noqa: E402

# A suite started in the background (``make test &``, ``nohup``) inherits SIGINT ignored, and every process a
# test starts would inherit that too: the tests that stop a node, a launch or ``tactile view`` with Ctrl-C
# (SIGINT) would wait for nothing.  Handle SIGINT as a foreground run does; children then start with the default.
if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

SHARED_DIR = Path(os.environ.get("TACTILE_SHARED_DIR", _REPO.parent / "shared"))
BIOTAC_DATA_DIR = SHARED_DIR / "data" / "biotac_slide_20_50"


def _have_ros() -> bool:
    try:
        import rclpy  # noqa: F401

        import tactile_descriptors_msgs.msg  # noqa: F401
    except ImportError:
        return False
    return True


HAVE_ROS = _have_ros()
ROS2_CLI_DIR = SHARED_DIR / "ros2-cli"


def _have_ros2cli() -> bool:
    try:
        import launch_ros  # noqa: F401
        import ros2cli  # noqa: F401
    except ImportError:
        return False
    return (Path(sys.prefix) / "bin" / "ros2").exists()


HAVE_ROS2CLI = _have_ros2cli()


def pytest_collection_modifyitems(config, items):
    in_ci = os.environ.get("CI", "").lower() in {"1", "true", "yes"}
    for item in items:
        if "ros" in item.keywords and not HAVE_ROS:
            if in_ci:
                # In CI the set-up installs ROS: its absence is a failure, not a skip.
                item.add_marker(pytest.mark.xfail(reason="rclpy missing in CI", strict=True, run=False))
            else:
                item.add_marker(pytest.mark.skip(reason="rclpy or tactile_descriptors_msgs not installed"))
        if "ros2cli" in item.keywords and not HAVE_ROS2CLI and not ROS2_CLI_DIR.is_dir():
            item.add_marker(pytest.mark.skip(reason=f"no ros2 CLI / launch system: {ROS2_CLI_DIR} not found"))
        if "realdata" in item.keywords and not BIOTAC_DATA_DIR.is_dir():
            item.add_marker(pytest.mark.skip(reason=f"real recordings not found at {BIOTAC_DATA_DIR}"))


_SHM_CLEANED: set[str] = set()


def pytest_runtest_setup(item):
    if "ros2cli" in item.keywords and not HAVE_ROS2CLI and ROS2_CLI_DIR.is_dir():
        # make setup installs it from there: its absence is a set-up failure, not a skip.
        pytest.fail(f"ros2 CLI not installed in {sys.prefix} though {ROS2_CLI_DIR} exists (run make setup)")
    module = item.nodeid.split("::")[0]
    # before each module that starts DDS participants
    if ("ros" in item.keywords or "ros2cli" in item.keywords) and module not in _SHM_CLEANED:
        from dds_shm import clean_zombie_shm  # test/ (pytest.ini pythonpath)

        _SHM_CLEANED.add(module)
        clean_zombie_shm()


@pytest.fixture
def repo_dir() -> Path:
    """The repository checkout."""
    return _REPO


@pytest.fixture(scope="session")
def biotac_data_dir() -> Path:
    """The shared real BioTac recordings (tests using it are marked ``realdata``)."""
    return BIOTAC_DATA_DIR


@pytest.fixture
def ros_context():
    """A fresh rclpy context per test, shut down afterwards, and its DDS participant gone before the next test.

    A node the test left (one whose constructor raised, one in a reference cycle) keeps the context's Fast DDS
    participant until the collector frees it, which could then happen during a later test, beside that test's
    own participants.  Fast DDS can deadlock when participants of one process discover each other while one of
    them is destroyed (seen once in this suite: a node's destruction waiting forever on another participant's
    discovery thread), so the collector runs here, between tests, and each test meets at most the participants
    it makes.
    """
    import gc

    import rclpy

    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        yield context
    finally:
        if context.ok():
            rclpy.shutdown(context=context)
        del context
        gc.collect()


@pytest.fixture
def ros_message_examples() -> list:
    """One fully filled rclpy message of each tactile type (needs rclpy); fresh objects per test."""
    from builtin_interfaces.msg import Time

    from tactile_descriptors_msgs.msg import (
        BioTacFrameBatch,
        Descriptor,
        DescriptorLayout,
        Label,
        Prediction,
        SkinCellFrame,
        SkinPartFrames,
    )

    b = BioTacFrameBatch()
    b.header.stamp = Time(sec=12, nanosec=345)
    b.header.frame_id = "biotac_index"
    b.sensor_name, b.body_part, b.serial_number = "biotac_index", "index", "BT0042"
    b.chip_select, b.first_frame_sequence, b.frame_count, b.electrode_count = 1, 7, 2, 19
    b.pac = list(range(44))
    b.pac[3] = BioTacFrameBatch.INVALID_COUNT
    b.pac_offset_ns = [i * 454_545 for i in range(44)]
    b.frame_offset_ns = [0, 10_000_000]
    b.pdc, b.tac, b.tdc = [100, 101], [2000, 2001], [1500, 1501]
    b.electrodes = list(range(38))
    b.pac_pa_per_count, b.force_n_per_count, b.pdc_tare_counts = 0.37, 0.05, 1980.0
    b.electrode_tare_counts = [float(i) for i in range(19)]
    b.bad_words = 1

    s = SkinCellFrame()
    s.cell_id, s.body_part, s.sequence = 17, "chest", 99
    s.accel_x, s.accel_y, s.accel_z = [-512, 0, 511, SkinCellFrame.INVALID_ACCEL], [1, 2, 3, 4], [5, 6, 7, 8]
    s.accel_offset_ns = [0, 1_000_000, 2_000_000, 3_000_000]
    s.force = [1, 2, 3]
    s.force_offset_ns = [0]
    s.force_tare_counts = [1.0, 2.0, 3.0]
    s.proximity = [400]
    s.temperature_c = 31.5

    d = Descriptor()
    d.robot, d.exploration_id = "shadow_hand", 5
    d.window_mode, d.layout_mode, d.channel_mode = "exploration", "concat", "averaged"
    d.body_parts, d.contact, d.cells_in_contact, d.cells_total = ["thumb", "index"], [False, True], [0, 1], [1, 1]
    d.mean_force_n = [0.0, 1.5]
    d.quality = [Descriptor.QUALITY_NO_CONTACT, 0]
    d.labels = ["index/A_pac", "index/M_pac"]
    d.values = [1234.5, 287.25]

    p = Prediction()
    p.exploration_id, p.has_model, p.class_name = 5, True, "cork"
    p.class_names, p.scores, p.model_version, p.updates = ["cork", "felt"], [0.5, -0.5], 3, 3

    lab = Label()
    lab.exploration_id, lab.class_name = 5, "cork"

    sp = SkinPartFrames()
    sp.header.stamp = Time(sec=12, nanosec=500)
    sp.header.frame_id = sp.body_part = "chest"
    sp.cell_ids, sp.sequence, sp.bad_frames = [17, 18], [99, 7], [0, 2]
    sp.accel_count, sp.force_count = [3, 1], [1, 0]
    sp.temperature_c = [31.5, 30.25]
    sp.force_tare_counts = [1.0, 2.0, 3.0, 0.0, 0.0, 0.0]
    sp.accel_x, sp.accel_y, sp.accel_z = [-512, 0, 511, SkinPartFrames.INVALID_ACCEL], [1, 2, 3, 4], [5, 6, 7, 8]
    sp.accel_offset_ns = [0, 1_000_000, 2_000_000, 500_000]
    sp.force, sp.force_offset_ns, sp.proximity = [1, 2, SkinPartFrames.INVALID_COUNT], [0], [400]
    sp.accel_mps2_per_count, sp.force_n_per_count = 0.038, 0.00244

    lay = DescriptorLayout()
    lay.header.frame_id = "shadow_hand"
    lay.layout_id, lay.robot, lay.layout_mode, lay.channel_mode = "0123456789abcdef", "shadow_hand", "concat", "paper"
    lay.body_parts, lay.labels = ["thumb", "index"], ["thumb/paper/A_S", "index/paper/A_S"]
    return [b, s, d, p, lab, sp, lay]
