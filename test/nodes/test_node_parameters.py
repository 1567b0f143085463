"""Node parameters in-process: descriptors (ranges, choices, read-only), run-time sets, paths and frames used."""

from __future__ import annotations

import threading
import time

import pytest
from node_helpers import BiotacStream, spin_until

from tactile_descriptors_ros.core.robot import load_robot

pytestmark = pytest.mark.ros


def _params(**values):
    from rclpy.parameter import Parameter

    return [Parameter(k.replace("__", "."), value=v) for k, v in values.items()]


def _describe(node, name):
    return node.describe_parameters([name])[0]


def _window(ros_context, **values):
    from tactile_descriptors_ros.nodes.window_node import WindowNode

    return WindowNode(context=ros_context,
                      parameter_overrides=_params(robot="shadow_hand", body_parts=["index"], **values))


def test_ranges_and_choices_are_in_the_descriptors(ros_context):
    from rcl_interfaces.msg import ParameterType

    w = _window(ros_context)
    try:
        d = _describe(w, "contact.force_threshold_n")
        assert d.type == ParameterType.PARAMETER_DOUBLE and not d.read_only
        assert len(d.floating_point_range) == 1 and d.floating_point_range[0].from_value == 0.0
        assert d.floating_point_range[0].to_value == 1000.0  # the schema's bound: finite, as every range
        d = _describe(w, "window.mode")
        assert d.read_only and d.additional_constraints == "one of: fixed, exploration"
        d = _describe(w, "qos.frames.depth")
        assert d.read_only and d.integer_range[0].from_value == 1
        d = _describe(w, "qos.frames.reliability")
        assert d.additional_constraints == "one of: reliable, best_effort, system_default"
        assert _describe(w, "robot").read_only and _describe(w, "exploration_id_stride").read_only
        for name in ("window.length_s", "window.hop_s", "contact.release_threshold_n", "window.lateness_s"):
            assert not _describe(w, name).read_only, name
    finally:
        w.destroy_node()


def test_window_settings_are_set_at_run_time_checked_together(ros_context):
    from rclpy.parameter import Parameter

    w = _window(ros_context)
    try:
        ok = w.set_parameters([Parameter("window.length_s", value=0.5), Parameter("window.hop_s", value=0.25)])
        assert all(r.successful for r in ok)
        assert (w.windower.length_ns, w.windower.hop_ns) == (500_000_000, 250_000_000)
        # an integer for a double: widened, as ``ros2 param set /window_node window.length_s 3`` sends it
        r = w.set_parameters([Parameter("window.length_s", value=3)])[0]
        assert r.successful, r.reason
        assert w.get_parameter("window.length_s").value == 3.0 and w.windower.length_ns == 3_000_000_000
        # release above onset: refused with the reason, nothing changed
        r = w.set_parameters([Parameter("contact.release_threshold_n", value=0.5)])[0]
        assert not r.successful and "release threshold" in r.reason
        assert w.windower.release_n == 0.1 and w.get_parameter("contact.release_threshold_n").value == 0.1
        # both thresholds in one atomic request: valid together, applied together
        r = w.set_parameters_atomically([Parameter("contact.force_threshold_n", value=0.8),
                                         Parameter("contact.release_threshold_n", value=0.5)])
        assert r.successful, r.reason
        assert (w.windower.onset_n, w.windower.release_n, w.force_threshold_n) == (0.8, 0.5, 0.8)
        r = w.set_parameters([Parameter("window.hop_s", value=-1.0)])[0]  # the descriptor's range
        assert not r.successful and w.windower.hop_ns == 250_000_000
        r = w.set_parameters([Parameter("window.mode", value="fixed")])[0]
        assert not r.successful and "read-only" in r.reason
    finally:
        w.destroy_node()


def test_integer_override_for_a_double_starts_the_node(ros_context):
    w = _window(ros_context, window__length_s=3)
    try:
        assert w.get_parameter("window.length_s").value == 3.0 and w.windower.length_ns == 3_000_000_000
    finally:
        w.destroy_node()


def test_out_of_range_override_is_a_config_error_naming_it(ros_context):
    from tactile_descriptors_ros.errors import ConfigError

    with pytest.raises(ConfigError, match="contact.force_threshold_n"):
        _window(ros_context, contact__force_threshold_n=-1.0)


def test_descriptors_carry_the_robot_frame(ros_context):
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    from tactile_descriptors_msgs.msg import BioTacFrameBatch, Descriptor

    w = _window(ros_context, qos__frames__reliability="reliable")
    io = rclpy.create_node("io", context=ros_context)
    got = []
    io.create_subscription(Descriptor, "tactile/descriptor", got.append, 10)
    pub = io.create_publisher(BioTacFrameBatch, "tactile/index/frames", 50)
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(w)
    ex.add_node(io)
    try:
        # the robot's root frame, the root of the TF tree tf_publisher puts on /tf_static
        root = load_robot("shadow_hand").geometry.root_frame
        assert w.get_parameter("frame_id").value == root == "forearm"
        assert spin_until(ex, lambda: pub.get_subscription_count() >= 1 and w.kernel_ready.is_set(), 60)
        for m in BiotacStream().exploration(40.0):
            pub.publish(m)
            ex.spin_once(timeout_sec=0.005)
        assert spin_until(ex, lambda: got, 10)
        assert got[0].header.frame_id == root
    finally:
        ex.shutdown()
        w.destroy_node()
        io.destroy_node()


def test_window_node_subscribes_at_once_and_windows_every_touch_while_warming_up(ros_context, monkeypatch):
    """A cold kernel cache (held here until released) must not cost the first touches."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    from tactile_descriptors_msgs.msg import BioTacFrameBatch, Descriptor
    from tactile_descriptors_ros.nodes import window_node

    release = threading.Event()
    real_warm_up = window_node.warm_up

    def slow_warm_up():
        release.wait(60.0)  # a compilation that lasts until the test has sent its touches
        return real_warm_up()

    monkeypatch.setattr(window_node, "warm_up", slow_warm_up)
    io = rclpy.create_node("io", context=ros_context)
    got = []
    io.create_subscription(Descriptor, "tactile/descriptor", got.append, 50)
    pub = io.create_publisher(BioTacFrameBatch, "tactile/index/frames", 100)
    made = {}
    # constructed on a thread: a node that warms up before subscribing would block here
    builder = threading.Thread(target=lambda: made.setdefault("w", _window(
        ros_context, qos__frames__reliability="reliable", qos__frames__depth=500)), daemon=True)
    builder.start()
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(io)
    try:
        subscribed = spin_until(ex, lambda: pub.get_subscription_count() >= 1, 20)
        assert subscribed, "the window node did not subscribe while its kernel warmed up"
        builder.join(30)  # the constructor waits up to WARM_UP_WAIT_S for the kernel, then runs on
        w = made["w"]
        ex.add_node(w)
        stream = BiotacStream()
        for freq in (40.0, 120.0, 300.0):
            for m in stream.exploration(freq):
                pub.publish(m)
                ex.spin_once(timeout_sec=0.005)
        assert spin_until(ex, lambda: len(w.held_windows) == 3, 20), "touches not windowed while warming up"
        assert not got and not w.kernel_ready.is_set()
        release.set()
        assert spin_until(ex, lambda: len(got) == 3, 60)
        assert [d.exploration_id for d in got] == [1, 2, 3]
        assert w.windows_held_at_start == 3 and not w.held_windows
    finally:
        release.set()
        ex.shutdown()
        if "w" in made:
            made["w"].destroy_node()
        io.destroy_node()


# ----------------------------------------------------------------- classifier
def _classifier(ros_context, name="classifier_node", **values):
    from tactile_descriptors_ros.nodes.classifier_node import ClassifierNode

    return ClassifierNode(name, context=ros_context, parameter_overrides=_params(**values))


def test_each_robot_and_namespace_has_its_own_model_folder_and_the_parameter_reads_it(ros_context, tmp_path,
                                                                                       monkeypatch):
    monkeypatch.setenv("ROS_HOME", str(tmp_path))
    from tactile_descriptors_ros.nodes.classifier_node import ClassifierNode

    hand, nao = _classifier(ros_context, robot="shadow_hand"), _classifier(ros_context, robot="nao")
    left = ClassifierNode(context=ros_context, namespace="/left", parameter_overrides=_params(robot="shadow_hand"))
    right = ClassifierNode(context=ros_context, namespace="/right", parameter_overrides=_params(robot="shadow_hand"))
    try:
        base = tmp_path / "tactile_descriptors_ros"
        want = {hand: base / "shadow_hand" / "classifier_node", nao: base / "nao" / "classifier_node",
                left: base / "shadow_hand" / "left" / "classifier_node",
                right: base / "shadow_hand" / "right" / "classifier_node"}
        for node, folder in want.items():
            assert node.model_path == folder  # one model file per descriptor layout inside, opened when one comes
            assert node.get_parameter("model_path").value == f"{folder}/"
        assert _describe(hand, "model_path").read_only
    finally:
        for node in (hand, nao, left, right):
            node.destroy_node()
    # a folder of one's own: a model_path ending in /
    mine = _classifier(ros_context, model_path=f"{tmp_path}/mine/")
    try:
        assert mine.model_path == tmp_path / "mine" and mine.given_path is None
        assert mine.get_parameter("model_path").value == f"{tmp_path}/mine/"
    finally:
        mine.destroy_node()


def test_reset_of_one_robot_keeps_the_other_robots_model(ros_context, tmp_path, monkeypatch):
    from std_srvs.srv import Trigger

    from tactile_descriptors_ros.core.learning import OnlineClassifier
    from tactile_descriptors_ros.core.model_store import layout_file_name, save_model
    from tactile_descriptors_ros.nodes.classifier_node import default_model_folder

    monkeypatch.setenv("ROS_HOME", str(tmp_path))
    model = OnlineClassifier(["index/A_pac", "index/A_e"])
    model.learn([1.0, 2.0], "cork")
    hand_file = default_model_folder("classifier_node", "/", "shadow_hand") / layout_file_name(model.labels)
    save_model(model, hand_file)
    before = hand_file.read_bytes()
    nao = _classifier(ros_context, robot="nao", enable_reset=True)
    try:
        assert nao.model is None  # the hand's model is not loaded by the NAO
        resp = nao._srv_reset(Trigger.Request(), Trigger.Response())
        assert resp.success and "nao" in resp.message
    finally:
        nao.destroy_node()
    assert hand_file.read_bytes() == before


def test_classifier_settings_are_set_at_run_time(ros_context, tmp_path):
    from rclpy.parameter import Parameter

    c = _classifier(ros_context, model_path=str(tmp_path / "m.json"))
    try:
        assert c.get_parameter("model_path").value == str(tmp_path / "m.json")
        for eid in range(1, 6):
            c.labels.add_descriptor(eid, object())
        r = c.set_parameters([Parameter("label_horizon", value=2)])[0]
        assert r.successful and c.labels.kept == 2 and c.labels.horizon == 2
        assert c.labels.add_label(3, "cork").action == "held"  # its descriptor is forgotten: beyond the horizon
        assert c.labels.add_label(5, "cork").action == "learn"
        r = c.set_parameters([Parameter("label_horizon", value=0)])[0]
        assert not r.successful and c.params["label_horizon"] == 2
        r = c.set_parameters([Parameter("eta", value=0.5)])[0]
        assert r.successful and c.params["eta"] == 0.5
        r = c.set_parameters([Parameter("pa_update", value="prediction")])[0]
        assert not r.successful and "read-only" in r.reason
        d = _describe(c, "pa_update")
        assert d.additional_constraints.startswith("one of: ") and "max_loss" in d.additional_constraints
    finally:
        c.destroy_node()


# -------------------------------------------------------------------- drivers
def test_tare_refuses_stale_frames(ros_context):
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from std_srvs.srv import Trigger

    from tactile_descriptors_ros.codecs.biotac_spi import FramePattern, encode_frame
    from tactile_descriptors_ros.codecs.bridge_serial import BridgeEncoder
    from tactile_descriptors_ros.nodes.biotac_driver import BiotacDriver

    params = {"robot": "shadow_hand", "body_parts": ["index"], "transport": "loopback", "tare_on_start_s": 0.0,
              "stamp_source": "device"}
    drv = BiotacDriver(context=ros_context, parameter_overrides=[Parameter(k, value=v) for k, v in params.items()])
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(drv)
    try:
        pattern, enc = FramePattern.default(), BridgeEncoder()
        frame = encode_frame(pattern, {"PAC": [2000] * pattern.pac_count, "PDC": 2000, "TAC": 500, "TDC": 600,
                                       "electrodes": [1000] * 19})
        drv.transport.write(b"".join(enc.encode(1, frame, t_us=10_000 * k) for k in range(30)))
        st = drv.state[1]
        assert spin_until(ex, lambda: st.frames_total == 30)
        assert drv._srv_tare(Trigger.Request(), Trigger.Response()).success  # current frames: tared
        assert spin_until(ex, lambda: time.monotonic() - drv._last_frame[1] > drv.stale_after_s, 10)
        resp = drv._srv_tare(Trigger.Request(), Trigger.Response())
        assert not resp.success and "stale" in resp.message and "biotac" in resp.message
    finally:
        drv.close()
        drv.destroy_node()


_SHORT_SCENE = """
scene: {name: two_touches, robot: shadow_hand, seed: 3, lead_in_s: 0.3}
effects: {normal_force: {ramp_s: 0.1}, texture_vibration: {}, electrode_deformation: {}, adc: {}}
defaults: {body_parts: [index], motion: lateral, force_n: 2.0, speed_m_s: 0.02, duration_s: 0.5, pause_s: 0.3}
explorations:
  - materials: [cork]
    repeat: 2
"""


def test_scene_end_is_announced_and_diagnostics_say_so(ros_context, tmp_path):
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from std_srvs.srv import Trigger

    from tactile_descriptors_ros.nodes.biotac_driver import BiotacDriver

    scene = tmp_path / "two_touches.yaml"
    scene.write_text(_SHORT_SCENE)
    params = {"robot": "shadow_hand", "body_parts": ["index"], "transport": "simulated", "sim.scene": str(scene),
              "sim.speed": 4.0, "stamp_source": "device", "tare_on_start_s": 0.1}
    drv = BiotacDriver(context=ros_context, parameter_overrides=[Parameter(k, value=v) for k, v in params.items()])
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(drv)
    try:
        assert spin_until(ex, lambda: drv.scene_ended_logged, 30), "the end of the scene was not noticed"

        def sensor_status():
            return next(s for s in drv.diagnostics.statuses() if s.name.endswith(": biotac_index"))

        assert spin_until(ex, lambda: "scene ended" in sensor_status().message, 10)
        status = sensor_status()
        assert "unplugged" not in status.message and status.level == b"\x03"
        resp = drv._srv_tare(Trigger.Request(), Trigger.Response())
        assert not resp.success and "scene has ended" in resp.message
    finally:
        drv.close()
        drv.destroy_node()


def _matched_text(count: int) -> str:
    return "no publisher" if count == 0 else f"{count} publisher{'s' if count > 1 else ''} matched"


def test_frames_matched_reads_the_reader_side_count():
    """frames_matched: true only for a positive `<part>_publishers` of that part; absent or unreadable is false."""
    from tactile_descriptors_ros.nodes.window_node import frames_matched

    assert frames_matched({"index_publishers": "1", "thumb_publishers": "0"}, "index")
    assert not frames_matched({"index_publishers": "1", "thumb_publishers": "0"}, "thumb")
    assert not frames_matched({"index_publishers": "1"}, "middle")  # a part this node does not serve
    assert not frames_matched({"index_publishers": "one"}, "index")


def test_silent_after_is_set_at_run_time(ros_context):
    """diagnostics.silent_after_s: a body part that sent frames is silent once that long has passed without more;
    the status says whether a publisher is still matched (a stopped sender or a lost delivery) or none is."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter

    from tactile_descriptors_msgs.msg import BioTacFrameBatch
    from tactile_descriptors_ros.nodes.window_node import frames_matched

    w = _window(ros_context, qos__frames__reliability="reliable")
    io = rclpy.create_node("io", context=ros_context)
    pub = io.create_publisher(BioTacFrameBatch, "tactile/index/frames", 50)
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(w)
    ex.add_node(io)

    def status():
        return w.diagnostics.statuses()[0].message

    try:
        assert spin_until(ex, lambda: pub.get_subscription_count() >= 1, 30)
        assert w.set_parameters([Parameter("diagnostics.silent_after_s", value=3600.0)])[0].successful
        pub.publish(BiotacStream().batch(0.0, 40.0))
        assert spin_until(ex, lambda: w.frames_taken >= 1, 30)
        assert "no frames from" not in status()
        r = w.set_parameters([Parameter("diagnostics.silent_after_s", value=0.1)])[0]
        assert r.successful, r.reason
        assert spin_until(ex, lambda: "no frames from index (" in status(), 30)
        # at least this test's publisher (the suite's other nodes share the domain: a node of an earlier test
        # can still count until its participant's lease ends)
        values = {kv.key: kv.value for kv in w.diagnostics.statuses()[0].values}
        matched = int(values["index_publishers"])
        assert matched >= 1 and float(values["index_silent_s"]) >= 0.1
        assert frames_matched(values, "index")  # what a player waits for before its first frames
        assert f"no frames from index ({_matched_text(matched)})" in status()
        # this publisher gone: the same silence counts one publisher less
        io.destroy_publisher(pub)
        assert spin_until(ex, lambda: f"no frames from index ({_matched_text(matched - 1)})" in status(), 30), \
            status()
    finally:
        ex.shutdown()
        w.destroy_node()
        io.destroy_node()


def test_a_tare_window_longer_than_the_kept_samples_is_refused(ros_context):
    """A tare averages the samples the stream keeps (a BioTac's last 2000 frames: 20 s at 100 frames/s; a skin
    cell's last 500 force samples: 2 s at 250 Hz): a longer window is refused, not silently shortened."""
    from rclpy.parameter import Parameter

    from tactile_descriptors_ros.errors import ConfigError
    from tactile_descriptors_ros.nodes.biotac_driver import BiotacDriver
    from tactile_descriptors_ros.nodes.skin_driver import SkinDriver

    common = [Parameter("transport", value="loopback"), Parameter("autostart", value=False)]
    drv = BiotacDriver(context=ros_context, parameter_overrides=[Parameter("robot", value="shadow_hand"), *common])
    try:
        assert drv.set_parameters([Parameter("tare.window_s", value=20.0)])[0].successful
        r = drv.set_parameters([Parameter("tare.window_s", value=20.5)])[0]
        assert not r.successful and "longer than the 20 s of samples" in r.reason and "word_rate_hz" in r.reason
        assert drv.params["tare.window_s"] == 20.0
    finally:
        drv.destroy_node()
    with pytest.raises(ConfigError, match=r"'tare_on_start_s': 3 s is longer than the 2 s .* 250 Hz"):
        SkinDriver(context=ros_context, parameter_overrides=[Parameter("robot", value="nao"),
                                                             Parameter("tare_on_start_s", value=3.0), *common])
