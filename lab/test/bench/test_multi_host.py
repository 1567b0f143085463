"""The scale graph across hosts: network namespaces joined by veth links (``tactile bench --scale-graph --hosts``)."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import time
from collections import Counter

import pytest
from hypothesis import given
from hypothesis import strategies as st

from tactile_descriptors_lab.bench.multi_host import (
    CLASSIFIER_HOST,
    MultiHostResult,
    assign_parts,
    descriptor_gaps,
    link_drop_recovery,
    missing_predictions,
    node_hosts,
)
from tactile_descriptors_lab.bench.netns import (
    SUBNET,
    VirtualHosts,
    namespaces_unavailable,
    remove_stale_namespaces,
)
from tactile_descriptors_lab.bench.scale_graph import scale_graph_specs
from tactile_descriptors_ros.sim.synthetic import WINDOW_HOP_S, WINDOW_LENGTH_S, scale_robot_files

NO_NAMESPACES = namespaces_unavailable()
needs_namespaces = pytest.mark.skipif(NO_NAMESPACES is not None, reason=f"no network namespaces: {NO_NAMESPACES}")
HOP_NS = int(WINDOW_HOP_S * 1e9)


# ------------------------------------------------------------------ placement
def test_body_parts_are_split_over_the_hosts_in_runs_whose_sizes_differ_by_at_most_one():
    parts = [f"part_{k:02d}" for k in range(7)]
    hosts = assign_parts(parts, 3)
    assert list(hosts) == parts
    assert Counter(hosts.values()) == {"host0": 3, "host1": 2, "host2": 2}
    assert [hosts[p] for p in parts] == sorted(hosts[p] for p in parts)  # consecutive runs
    with pytest.raises(ValueError):
        assign_parts(parts, 8)
    with pytest.raises(ValueError):
        assign_parts(parts, 0)


def test_a_body_parts_driver_and_window_node_share_its_host_and_the_classifier_has_its_own(tmp_path):
    specs = scale_graph_specs(scale_robot_files(40, 4, tmp_path, classifier=True))
    placement = node_hosts(specs, assign_parts([f"part_{k}" for k in range(4)], 2))
    assert placement == {"skin_driver_part_0": "host0", "skin_driver_part_1": "host0",
                         "skin_driver_part_2": "host1", "skin_driver_part_3": "host1",
                         "window_node_part_0": "host0", "window_node_part_1": "host0",
                         "window_node_part_2": "host1", "window_node_part_3": "host1",
                         "classifier_node": CLASSIFIER_HOST}


def test_a_driver_serving_body_parts_on_two_hosts_is_refused(tmp_path):
    specs = scale_graph_specs(scale_robot_files(40, 2, tmp_path, one_driver=True))
    with pytest.raises(ValueError, match="2 hosts"):
        node_hosts(specs, {"part_0": "host0", "part_1": "host1"})


# ---------------------------------------------------------------- counting
@given(st.lists(st.integers(0, 200), min_size=2, max_size=60, unique=True), st.integers(0, 10**12))
def test_descriptor_gaps_count_the_windows_missing_from_a_run_of_hops(kept, offset):
    ends = [offset + k * HOP_NS for k in sorted(kept)]
    assert descriptor_gaps(ends, HOP_NS) == max(kept) - min(kept) + 1 - len(kept)
    assert descriptor_gaps(ends + ends[:3], HOP_NS) == descriptor_gaps(ends, HOP_NS)  # a duplicate is no gap


def test_missing_predictions_are_counted_by_window_end_with_multiplicity():
    sent = Counter({10: 2, 20: 1, 30: 1})
    assert missing_predictions(sent, Counter({10: 2, 20: 1, 30: 1, 40: 5})) == 0
    assert missing_predictions(sent, Counter({10: 1, 30: 1})) == 2


def _rows(down_at: float, up_at: float, resent: int, lag_s: float = 0.3, n: int = 40) -> list[tuple[float, int]]:
    """Descriptors every hop with a steady lag; those due while the link is down arrive after ``up_at``,
    only the last ``resent`` of them (the writer's queue), 0.4 s after it."""
    rows = []
    held = []
    for k in range(n):
        end_s = 100.0 + k * WINDOW_HOP_S
        arrival = end_s + lag_s
        if down_at <= arrival < up_at:
            held.append(end_s)
            continue
        rows.append((arrival, int(end_s * 1e9)))
    rows += [(up_at + 0.4, int(e * 1e9)) for e in held[len(held) - resent:]]
    return rows


def test_a_link_drop_is_accounted_as_a_bounded_backlog_and_the_time_to_the_usual_lag():
    rows = _rows(down_at=105.0, up_at=110.0, resent=4)
    backlog, recovered, lost_late = link_drop_recovery(rows, 105.0, 110.0, WINDOW_HOP_S, WINDOW_LENGTH_S)
    assert backlog == 4 and lost_late == 0
    # the first descriptor on time after the return: end 110.0 arrives 110.3
    assert recovered == pytest.approx(0.3, abs=1e-6)
    assert descriptor_gaps([e for _, e in rows], HOP_NS) == 10 - 4
    # a window due 3.3 s after the return that never came is lost after the graph should have recovered
    late = [r for r in rows if r[1] != int(113.0e9)]
    assert link_drop_recovery(late, 105.0, 110.0, WINDOW_HOP_S, WINDOW_LENGTH_S)[2] == 1


def test_a_part_that_never_recovers_reports_no_recovery_time():
    rows = [r for r in _rows(105.0, 110.0, resent=0) if r[0] < 105.0]
    assert link_drop_recovery(rows, 105.0, 110.0, WINDOW_HOP_S, WINDOW_LENGTH_S) == (0, None, 0)


def test_cross_host_traffic_per_cell_counts_each_byte_once_at_its_sender():
    r = MultiHostResult(hosts=2, n_cells=100, seconds=10.0,
                        traffic={h: {"tx_bytes": b, "rx_bytes": 3 * b} for h, b in
                                 (("host0", 1000), ("host1", 2000), (CLASSIFIER_HOST, 7000))})
    assert r.cross_host_bytes_per_s == pytest.approx(1000.0)
    assert r.cross_host_bytes_per_cell_s == pytest.approx(10.0)


# ------------------------------------------------------------------ namespaces
def _netns() -> set[str]:
    out = subprocess.run(["ip", "-j", "netns", "list"], capture_output=True, text=True, check=True).stdout
    return {d["name"] for d in json.loads(out or "[]")}


def _netns_without_stale() -> set[str]:
    """The namespaces there are once those a killed bench left are gone.

    Making hosts removes such leftovers first (``remove_stale_namespaces``), so a snapshot taken before hosts are
    made must not count them: a run killed earlier on the same machine would otherwise fail the comparison after.
    """
    remove_stale_namespaces()
    return _netns()


def _own_links() -> list[tuple[str, str | None]]:
    out = subprocess.run(["ip", "-j", "addr"], capture_output=True, text=True, check=True).stdout
    return sorted((d["ifname"], a.get("local")) for d in json.loads(out) for a in d.get("addr_info", []) or [{}])


def _wait_for(condition, timeout_s: float = 30.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, "condition not reached"
        time.sleep(0.05)


def _udp(net: VirtualHosts, src: str, dst: str, count: int, idle_s: float = 10.0) -> int:
    """Datagrams ``dst`` received of ``count`` that ``src`` sent to it (a receiver on ``dst``, a sender on ``src``).

    Each call tags its datagrams, so those the kernel held while a link was down (waiting for the neighbour's
    address) and delivered later are not counted for a later call.  The receiver stops when all ``count``
    arrived or after ``idle_s`` without one.
    """
    tag = os.urandom(8).hex().encode()
    recv = (f"import socket;s=socket.socket(socket.AF_INET,socket.SOCK_DGRAM);s.bind(('0.0.0.0',47111));"
            f"s.settimeout({idle_s});print('ready',flush=True);n=0\n"
            f"try:\n while n < {count}:\n  if s.recv(2048).startswith({tag!r}): n+=1\nexcept OSError: pass\nprint(n)")
    send = (f"import socket;s=socket.socket(socket.AF_INET,socket.SOCK_DGRAM)\n"
            f"for k in range({count}):\n try: s.sendto({tag!r}+b'x'*1000,('{net.address(dst)}',47111))\n"
            f" except OSError: pass")
    r = subprocess.Popen([*net.exec_prefix(dst), sys.executable, "-c", recv], stdout=subprocess.PIPE, text=True)
    assert r.stdout.readline().strip() == "ready"  # bound before anything is sent
    subprocess.run([*net.exec_prefix(src), sys.executable, "-c", send], check=True, timeout=60)
    out, _ = r.communicate(timeout=120)
    return int(out.split()[-1])


@needs_namespaces
def test_hosts_talk_over_their_links_only_and_are_removed_with_everything_on_them():
    before_ns, before_links = _netns_without_stale(), _own_links()
    with VirtualHosts(["a", "b"], tag=f"t{id(object()) % 10**6}") as net:
        made = set(net.namespaces)
        assert made <= _netns() and len(made) == 3  # two hosts and the switch
        assert _own_links() == before_links  # nothing on this machine's own network
        c0 = net.counters("a")
        assert _udp(net, "a", "b", 50) == 50
        sent = net.counters("a") - c0
        assert sent.tx_packets >= 50 and sent.tx_bytes >= 50 * 1000
        addr = subprocess.run(["ip", "-n", net.namespace("b"), "-j", "addr", "show", "eth0"], capture_output=True,
                              text=True, check=True).stdout
        assert json.loads(addr)[0]["addr_info"][0]["local"] in {str(a) for a in SUBNET}
        net.set_link("a", False)  # the cable pulled at the switch
        assert _udp(net, "a", "b", 20, idle_s=2.0) == 0  # (absence can only be seen within a bound)
        net.set_link("a", True)
        _wait_for(lambda: net.has_carrier("a"))  # the kernel reports the carrier a moment later
        assert _udp(net, "a", "b", 20) == 20  # routes kept: the host is reachable again without set-up
    assert _netns() == before_ns and _own_links() == before_links


@needs_namespaces
def test_hosts_are_removed_when_the_block_fails():
    before = _netns_without_stale()
    with pytest.raises(RuntimeError, match="a step failed"):
        with VirtualHosts(["a"], tag=f"f{id(object()) % 10**6}"):
            raise RuntimeError("a step failed")
    assert _netns() == before


@needs_namespaces
def test_namespaces_left_by_a_killed_bench_are_removed_and_no_others():
    dead = subprocess.Popen(["true"])
    dead.wait()
    stale, alive = f"tactile-{dead.pid}-host0", f"tactile-{os.getpid()}-stalecheck"
    for name in (stale, alive):
        subprocess.run(["ip", "netns", "add", name], check=True)
    try:
        assert stale in remove_stale_namespaces()
        assert stale not in _netns() and alive in _netns()  # this process still runs: its namespace stays
    finally:
        for name in (stale, alive):
            subprocess.run(["ip", "netns", "del", name], capture_output=True)


# ------------------------------------------------------------------- the graph
@pytest.mark.parametrize(("args", "says"), [
    (["--link-drop-s", "5"], "a link drop needs hosts"),
    pytest.param(["--hosts", "3", "--parts", "2"], "2 body parts cannot be placed on 3 hosts",
                 marks=needs_namespaces),
    pytest.param(["--hosts", "2", "--parts", "2", "--one-driver"], "one driver for every body part cannot be split",
                 marks=needs_namespaces),
    pytest.param(["--hosts", "1", "--link-drop-s", "5", "--seconds", "8"], "a 5.0 s link drop needs",
                 marks=needs_namespaces),
])
def test_impossible_host_layouts_are_refused_before_anything_starts(args, says):
    out = subprocess.run([sys.executable, "-m", "tactile_descriptors_ros.tools.cli", "bench", "--scale-graph",
                          "--cells", "4", *args], capture_output=True, text=True, timeout=120)
    assert out.returncode != 0 and says in out.stderr, out.stderr[-2000:]


def _bench(*args: str, timeout_s: float = 600.0) -> dict:
    """``tactile bench --scale-graph ARGS --json``; past ``timeout_s`` it gets SIGTERM (it then stops its nodes
    and removes its hosts) before anything harder, so a hung run leaves nothing behind."""
    proc = subprocess.Popen([sys.executable, "-m", "tactile_descriptors_ros.tools.cli", "bench", "--scale-graph",
                             *args, "--json"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        out, err = proc.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        proc.terminate()
        try:
            out, err = proc.communicate(timeout=60)
        except subprocess.TimeoutExpired:
            proc.kill()
            out, err = proc.communicate()
        pytest.fail(f"the bench ran past {timeout_s:g} s: {err[-3000:]}")
    assert proc.returncode == 0, err[-3000:]
    return json.loads(out)


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.timeout(900)
@needs_namespaces
@pytest.mark.parametrize("discovery", ["subnet", "server"])
def test_a_two_host_graph_brings_every_body_parts_descriptors_to_the_classifier_and_predictions_back(discovery):
    before = _netns_without_stale()
    d = _bench("--cells", "20", "--parts", "2", "--hosts", "2", "--seconds", "6", "--discovery", discovery)
    mh = d["multi_host"]
    assert mh["discovery"] == discovery
    assert mh["placement"] == {"skin_driver_part_0": "host0", "skin_driver_part_1": "host1",
                               "window_node_part_0": "host0", "window_node_part_1": "host1",
                               "classifier_node": CLASSIFIER_HOST}
    for name, p in d["parts"].items():
        assert p["lost_frames"] == 0, (name, p)
        # seen on the classifier's host: every window of each host's body part crossed
        assert p["windows"] >= math.floor(p["windows_expected"]) - 1, (name, p)
        assert mh["descriptor_gaps"][name] == 0
    assert mh["classifier"]["descriptors"] >= sum(p["windows"] for p in d["parts"].values()) - 2
    for host in ("host0", "host1"):
        back = mh["predictions"][host]
        assert back["sent"] > 0 and back["missing"] == 0, (host, back)
    # descriptors, diagnostics and predictions crossed each link; the frames stayed on their host
    for host in ("host0", "host1", CLASSIFIER_HOST):
        assert mh["traffic"][host]["tx_bytes"] > 0 and mh["traffic"][host]["rx_bytes"] > 0
    assert mh["discovery_s"] is not None
    assert d["targets"]["skin_20_graph_2_hosts"]["met"] is True, d["targets"]
    assert _netns() == before  # the bench removed its hosts


@pytest.mark.ros
@pytest.mark.slow
@pytest.mark.timeout(900)
@needs_namespaces
def test_a_host_whose_link_drops_for_5_s_is_counted_and_the_graph_recovers_within_a_window():
    d = _bench("--cells", "20", "--parts", "2", "--hosts", "2", "--seconds", "14", "--link-drop-s", "5")
    mh = d["multi_host"]
    drop = mh["link_drop"]
    assert drop["host"] == "host0" and drop["down_s"] >= 5.0
    # the frames never cross a link: no body part lost one, the dropped host's included
    assert all(p["lost_frames"] == 0 for p in d["parts"].values()), d["parts"]
    # ten windows were due while the link was down; those beyond the writer's queue are counted missing
    assert drop["descriptors_missing"]["part_0"] == mh["descriptor_gaps"]["part_0"]
    assert drop["descriptors_missing"]["part_0"] + drop["backlog"]["part_0"] >= math.floor(5.0 / WINDOW_HOP_S) - 1
    assert 0 <= drop["backlog"]["part_0"] <= drop["queue_depth"]
    # the classifier's queue (50 predictions) holds the 20 due while the link was down: none missing
    assert drop["predictions_missing"] == 0
    # recovered: on time again, and no window lost that was due a window or more after the link returned
    assert drop["recovered_after_s"]["part_0"] is not None
    assert drop["missing_after_recovery"]["part_0"] == 0
    # the other host lost nothing
    assert mh["descriptor_gaps"]["part_1"] == 0 and mh["predictions"]["host1"]["missing"] == 0
    assert d["targets"]["link_drop_recovery"]["met"] is True, d["targets"]
