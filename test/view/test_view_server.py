"""tactile view's server and bag player, without ROS: slow and vanished pages, bags with and without geometry."""

from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import sys
import urllib.request
from pathlib import Path

import numpy as np
import pytest

from tactile_descriptors_ros.view.bag import BagPlayer
from tactile_descriptors_ros.view.server import CLIENT_QUEUE, Hub, ViewServer


def _get(url: str):
    with urllib.request.urlopen(url, timeout=30) as r:
        return json.loads(r.read())


def test_a_page_that_does_not_read_loses_its_oldest_frames_counted():
    hub = Hub()
    stuck = hub.connect("stuck")
    reader = hub.connect("reader")
    got = []
    for k in range(50):
        hub.publish("frame", {"k": k})
        got.append(reader.take(0.0))  # this page keeps up
    assert [json.loads(g.split(b"data: ")[1])["k"] for g in got] == list(range(50))
    assert stuck.dropped == 50 - CLIENT_QUEUE and len(stuck.queue) == CLIENT_QUEUE
    assert json.loads(stuck.take(0.0).split(b"data: ")[1])["k"] == 50 - CLIENT_QUEUE  # the newest are kept
    assert hub.stats()["dropped"] == 50 - CLIENT_QUEUE and reader.dropped == 0


def test_a_new_page_gets_the_latest_config_and_frame_at_once():
    hub = Hub()
    hub.publish("config", {"robot": "nao"})
    hub.publish("frame", {"k": 1})
    hub.publish("frame", {"k": 2})
    c = hub.connect()
    assert [x.split(b"\n")[0] for x in (c.take(0.0), c.take(0.0))] == [b"event: config", b"event: frame"]
    assert c.take(0.0) is None


def test_slow_and_vanished_pages_over_real_sockets_never_hold_the_publisher():
    hub = Hub()
    server = ViewServer(hub, lambda: {"robot": "x"}, port=0).start()
    try:
        slow = socket.create_connection((server.host, server.port))
        slow.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        slow.sendall(b"GET /events HTTP/1.1\r\nHost: x\r\n\r\n")  # and never reads
        big = {"pad": "x" * 200_000}
        while not hub.stats()["clients"]:
            hub.publish("frame", {"waiting": True})
        for k in range(200):  # 40 MB at a page that reads nothing: the socket fills, the queue drops
            hub.publish("frame", dict(big, k=k))
        stats = hub.stats()
        assert stats["published"] >= 200 and stats["dropped"] >= 200 - 2 * CLIENT_QUEUE - 64
        # a page that reads still gets the newest frame
        with urllib.request.urlopen(server.url + "api/frame", timeout=30) as r:
            assert json.loads(r.read())["k"] == 199
        slow.close()  # the page goes away: its writer hits a closed socket and is dropped, counted
        k = 0
        while hub.stats()["disconnects"] < 1:
            hub.publish("frame", {"after": k})
            k += 1
            assert k < 100_000
        assert _get(server.url + "api/stats")["clients"] == []
    finally:
        server.close()


def _bag(path: Path, sensor: str, part: str, seconds: float = 3.0, with_prediction: bool = False) -> Path:
    """A bag of one BioTac's frames: no contact, then 1.5 N pressed at electrode e10, then no contact."""
    from tactile_descriptors_ros.bags.io import BagWriter

    t0 = 1_000_000_000
    with BagWriter(path) as bag:
        s = bag.store
        cls = s.types["tactile_descriptors_msgs/msg/BioTacFrameBatch"]
        time_cls, header = s.types["builtin_interfaces/msg/Time"], s.types["std_msgs/msg/Header"]
        topic = f"/tactile/{part}/frames"
        bag.add_topic(topic, "tactile_descriptors_msgs/msg/BioTacFrameBatch")
        rng = np.random.default_rng(0)
        for k in range(int(seconds * 10)):
            t = t0 + k * 100_000_000
            pressed = seconds / 3 <= k / 10 < 2 * seconds / 3
            el = (1500 + rng.normal(0, 2, (10, 19))).astype(np.uint16)
            if pressed:
                el[:, 9] += 150
            msg = cls(header=header(stamp=time_cls(sec=t // 10**9, nanosec=t % 10**9), frame_id=sensor),
                      sensor_name=sensor, body_part=part, serial_number="", chip_select=1,
                      first_frame_sequence=10 * k, frame_count=10, electrode_count=19,
                      pac=(2048 + rng.normal(0, 20, 220)).astype(np.uint16),
                      pac_offset_ns=np.arange(220, dtype=np.int64) * 454_545,
                      frame_offset_ns=np.arange(10, dtype=np.int64) * 10_000_000,
                      pdc=np.full(10, 1000 + (30 if pressed else 0), np.uint16), tac=np.full(10, 2000, np.uint16),
                      tdc=np.full(10, 2400, np.uint16), electrodes=el.ravel(), pac_pa_per_count=0.37,
                      pdc_pa_per_count=0.0, force_n_per_count=0.05, pdc_tare_counts=1000.0,
                      electrode_tare_counts=np.full(19, 1500.0), bad_words=0)
            bag.write(topic, t, bag.serialize(msg))
        if with_prediction:
            p = s.types["tactile_descriptors_msgs/msg/Prediction"](
                header=header(stamp=time_cls(sec=2, nanosec=500_000_000), frame_id="forearm"), exploration_id=1,
                window_end=time_cls(sec=2, nanosec=500_000_000), has_model=True, class_name="cork",
                class_names=["cork", "felt"], scores=np.array([1.0, -1.0]), model_version=1, updates=1)
            bag.add_topic("/tactile/prediction", "tactile_descriptors_msgs/msg/Prediction")
            bag.write("/tactile/prediction", t0 + 2_100_000_000, bag.serialize(p))
    return path


def test_a_bag_of_an_unknown_sensor_is_laid_out_in_a_grid_and_says_so(tmp_path):
    frames = []
    player = BagPlayer(_bag(tmp_path / "imported", "biotac_0", "finger"), lambda k, p: frames.append(p), speed=0)
    try:
        cfg = player.model.config()
        assert player.robot is None and not cfg["geometry"]
        assert "no geometry" in cfg["notice"] and "laid out in a grid" in cfg["notice"]
        assert [p["name"] for p in cfg["parts"]] == ["finger"] and len(cfg["parts"][0]["taxels"]) == 1
        last = player.play_until(1.5)
        assert last["parts"][0]["in_contact"] and last["parts"][0]["cop"] is None  # no place without geometry
        assert last["progress"]["position_s"] == pytest.approx(1.5) and frames
    finally:
        player.reader.close()


def test_a_bag_of_the_hand_is_laid_out_by_its_geometry_and_seeks(tmp_path):
    frames = []
    player = BagPlayer(_bag(tmp_path / "hand", "biotac_index", "index", with_prediction=True),
                       lambda k, p: frames.append(p), speed=0)
    try:
        cfg = player.model.config()
        assert player.robot.name == "shadow_hand" and cfg["geometry"] and cfg["notice"] is None
        index = next(p for p in cfg["parts"] if p["name"] == "index")
        assert len(index["taxels"]) == 19 and index["frame_id"] == "ffdistal"
        frame = player.play_until(1.6)
        part = next(p for p in frame["parts"] if p["name"] == "index")
        assert part["in_contact"] and part["force_n"] == pytest.approx(1.5, abs=1e-6)
        assert int(np.argmax([f or 0 for f in part["force"]])) == 9  # e10 carries the most
        thumb = next(p for p in frame["parts"] if p["name"] == "thumb")
        assert all(f is None for f in thumb["force"])  # never sent: stale, grey
        end = player.play_until(None)
        assert end["prediction"]["class_name"] == "cork" and end["progress"]["duration_s"] == pytest.approx(2.9)
    finally:
        player.reader.close()


def test_view_command_snapshots_a_bag_and_serves_it(tmp_path):
    bag = _bag(tmp_path / "hand", "biotac_index", "index")
    png = tmp_path / "out.png"
    cli = [sys.executable, "-m", "tactile_descriptors_ros.tools.cli", "view", "--bag", str(bag)]
    snap = subprocess.run(cli + ["--snapshot", str(png), "--at", "1.6", "--json"], capture_output=True, text=True,
                          timeout=300)
    assert snap.returncode == 0, snap.stderr
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and json.loads(snap.stdout)["in_contact"] == ["index"]
    # the port from TACTILE_VIEW_PORT when --port is not given (0: any free one)
    proc = subprocess.Popen(cli, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
                            env={**os.environ, "TACTILE_VIEW_PORT": "0"})
    try:
        line = proc.stdout.readline()
        url = re.search(r"http://\S+/", line).group(0)
        cfg = _get(url + "api/config")
        assert cfg["robot"] == "shadow_hand" and cfg["source"] == str(bag)
        assert _get(url + "api/seek?t=1.0") == {"seek": 1.0}
        with urllib.request.urlopen(url, timeout=30) as r:
            assert b"tactile view" in r.read()
    finally:
        os.killpg(proc.pid, signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    assert proc.returncode == 0 and "Traceback" not in err, err


@pytest.mark.parametrize("value", ["http", "-1", "65536"])
def test_a_bad_port_in_the_environment_is_named(tmp_path, value):
    out = subprocess.run([sys.executable, "-m", "tactile_descriptors_ros.tools.cli", "view", "--bag",
                          str(tmp_path / "none")], capture_output=True, text=True, timeout=120,
                         env={**os.environ, "TACTILE_VIEW_PORT": value})
    assert out.returncode == 2 and "Traceback" not in out.stderr
    assert f"'TACTILE_VIEW_PORT': {value!r} is not a port (0 to 65535)" in out.stderr, out.stderr
