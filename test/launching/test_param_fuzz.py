"""Every writable parameter of every node, set to hostile values through the real ``ros2 param set``.

The Shadow Hand graph runs under ``ros2 launch`` on its simulated scene (BioTac driver, window node,
classifier), with a skin driver beside it (``ros2 run``, loopback transport); each writable parameter of each
node (from the node schemas) is set to 0, -1, 2^62, 1e-300, 1e300, nan, +inf, -inf, '', a word and a
100,000-character string.  Every set must be answered -- "Set parameter successful" with the value inside its
declared range, or "Setting parameter failed: <reason>" -- and every node process must live on; a value that
was accepted is set back.  Afterwards every node still answers, and the graph still predicts new explorations.

Each parameter gets ``TACTILE_PARAM_FUZZ_VALUES`` of the 11 values (default 2, in rotation so that together the
parameters get every value); set it to 11 for all of them (about 15 minutes on 2 cores); CI's Jazzy leg sets
it to 1.  Every call starts a DDS participant, six at a time: on a busy machine Fast DDS has left a node
unreachable by new participants for minutes (docs/nodes.md), so the suite makes fewer calls.
``test/params/test_node_schemas.py`` sets all 11 on every parameter of every node in process.
"""

from __future__ import annotations

import os
import random
import re
import signal
import subprocess
import time
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor

import pytest
import yaml
from test_ros2_launch import (
    BIN,
    CLI_S,
    FIRST_PREDICTION_S,
    PKG,
    Graph,
    long_scene,
    replay_scene,
    start_launch,
)

from tactile_descriptors_ros.params import SCHEMAS

pytestmark = [pytest.mark.ros, pytest.mark.ros2cli, pytest.mark.slow, pytest.mark.timeout(3600)]

#: YAML 1.1 spellings (the CLI reads the value as YAML): ``1.0e+300``, ``.nan`` and ``.inf`` are doubles
#: (``1e300`` and ``inf`` would be strings); after ``--`` so that ``-1`` and ``-.inf`` are not options.
VALUES = ("0", "-1", str(2**62), "1.0e-300", "1.0e+300", ".nan", ".inf", "-.inf", "", "window", "x" * 100_000)
#: values per parameter (in rotation over VALUES): a sample in the suite, all of them on request
PER_PARAMETER = max(1, min(len(VALUES), int(os.environ.get("TACTILE_PARAM_FUZZ_VALUES", "2"))))
#: A namespace of this run's own: the machine's other test runs pick random domain ids too, and a graph of
#: theirs in the same domain must not answer for ours (nor mix its frames into ours).
NAMESPACE = f"fuzz_{os.getpid()}_{random.randrange(1 << 30)}"
NODES = {f"/{NAMESPACE}/{exe}": exe for exe in ("biotac_driver", "window_node", "classifier_node", "skin_driver")}
CLI = ("--no-daemon", "--spin-time", "1", "--timeout", "30")
#: parallel ``ros2 param`` calls (each mostly waits on discovery)
WORKERS = 6


@pytest.fixture(scope="module")
def graph(tmp_path_factory) -> Iterator[tuple[Graph, subprocess.Popen]]:
    from tactile_descriptors_ros.core.fast import warm_up

    warm_up()
    tmp = tmp_path_factory.mktemp("param_fuzz")
    # a scene that outlasts the fuzzing on a loaded machine: the graph must still predict afterwards
    scene = long_scene("shadow_hand", tmp)
    doc = yaml.safe_load(scene.read_text())
    for entry in doc["explorations"]:
        entry["repeat"] = 8 * int(entry.get("repeat", 1))
    scene.write_text(yaml.safe_dump(doc, sort_keys=False))
    proc, log, env = start_launch("shadow_hand", tmp, f"sim:={scene}", f"namespace:={NAMESPACE}")  # last sim wins
    g = Graph("shadow_hand", proc, log, env, tmp / "ros_home", "")
    skin_log = open(tmp / "skin.log", "w")
    skin = subprocess.Popen([str(BIN / "ros2"), "run", PKG, "skin_driver", "--ros-args", "-r", f"__ns:=/{NAMESPACE}",
                             "-p", "robot:=nao", "-p", "transport:=loopback"], stdout=skin_log,
                            stderr=subprocess.STDOUT, env=env, start_new_session=True)
    try:
        g.first_prediction = g.ros2("topic", "echo", "--once", "--no-daemon", f"/{NAMESPACE}/tactile/prediction",
                                    "tactile_descriptors_msgs/msg/Prediction", timeout=FIRST_PREDICTION_S)
        g.wait_for_nodes(set(NODES))
        yield g, skin
    finally:
        for p in (proc, skin):
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGINT)
                try:
                    p.wait(timeout=30)
                except subprocess.TimeoutExpired:
                    os.killpg(p.pid, signal.SIGKILL)
                    p.wait()
        skin_log.close()


def _node_pids(graph: Graph, skin: subprocess.Popen) -> dict[str, int]:
    """Node name -> the pid of its process (``__node:=`` on the command line, or the skin driver's)."""
    import psutil

    pids = {}
    for root in (graph.proc, skin):
        for p in [psutil.Process(root.pid), *psutil.Process(root.pid).children(recursive=True)]:
            cmd = " ".join(p.cmdline())
            for node, exe in NODES.items():
                if f"__node:={exe}" in cmd or (root is skin and exe in cmd and "python" in cmd):
                    pids[node] = p.pid
    assert set(pids) == set(NODES), pids
    return pids


def _alive(pid: int) -> bool:
    import psutil

    try:
        return psutil.Process(pid).status() != psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        return False


def _whole(text: str, keep: int = 4000) -> str:
    """A failed call's output for the failure message: whole (a crash dump names the call it crashed in),
    but the middle of a very long one (the 100,000-character value echoed) cut out."""
    if len(text) <= 2 * keep:
        return text
    return f"{text[:keep]}\n...({len(text) - 2 * keep} chars)...\n{text[-keep:]}"


def _value(text: str) -> str:
    """The value of ``ros2 param get``'s answer (``Double value is: 0.5`` -> ``0.5``)."""
    m = re.search(r"value is: (.*?)\n?\Z", text, re.S)
    assert m, text
    return m.group(1)


def test_every_writable_parameter_survives_hostile_sets_through_the_cli(graph):
    g, skin = graph
    pids = _node_pids(g, skin)

    def fuzz(job: tuple[str, list[str]]) -> list[str]:
        node, names = job
        problems: list[str] = []
        for name in names:
            problems += fuzz_one(node, name)
        return problems

    def fuzz_one(node: str, name: str) -> list[str]:
        param = SCHEMAS[NODES[node]][name]
        original = _value(g.ros2_node("param", "get", *CLI, node, name))
        problems = []
        first = order[(node, name)] * PER_PARAMETER
        for value in [VALUES[(first + k) % len(VALUES)] for k in range(PER_PARAMETER)]:
            out = g.ros2_node("param", "set", *CLI, node, name, "--", value, check=False)
            shown = value if len(value) < 20 else f"{value[:10]}...({len(value)} chars)"
            failed = re.search(r"Setting parameter failed: (\S.*)", out)
            if "Set parameter successful" in out:
                got = _value(g.ros2_node("param", "get", *CLI, node, name))
                if param.range is not None:
                    number = float(got)
                    if not param.range[0] <= number <= param.range[1]:
                        problems.append(f"{node} {name} {shown}: accepted {got}, outside {param.range}")
                restored = g.ros2_node("param", "set", *CLI, node, name, "--", original, check=False)
                if "Set parameter successful" not in restored:
                    problems.append(f"{node} {name}: could not set back {original!r}: {_whole(restored)}")
            elif not failed:
                problems.append(f"{node} {name} {shown}: no answer with a reason: {_whole(out)}")
            dead = [n for n, pid in pids.items() if not _alive(pid)]
            if dead:
                problems.append(f"{node} {name} {shown}: {', '.join(dead)} died")
                return problems
        return problems

    # parameters checked together (one apply hook) are set one after the other: a value accepted for one moves
    # what the others accept; independent ones in parallel
    groups: dict[tuple[str, str], list[str]] = {}
    for node, exe in NODES.items():
        for p in SCHEMAS[exe].tunable():
            groups.setdefault((node, p.apply or p.name), []).append(p.name)
    jobs = [(node, names) for (node, _), names in groups.items()]
    assert sum(len(names) for _, names in jobs) >= 20
    order = {(node, name): i for i, (node, name) in enumerate((n, m) for n, names in jobs for m in names)}
    started = time.monotonic()
    with ThreadPoolExecutor(WORKERS) as pool:
        problems = [p for found in pool.map(fuzz, jobs) for p in found]
    took = time.monotonic() - started
    assert not problems, "\n".join(problems) + f"\n--- launch log:\n{g.output()[-4000:]}"
    assert all(_alive(pid) for pid in pids.values())
    print(f"{sum(len(n) for _, n in jobs)} parameters x {PER_PARAMETER} values through ros2 param set in {took:.0f} s")
    # every node still answers, and the graph still predicts: the fuzzing outlasts the scene on a loaded machine,
    # so the driver plays it again, and a prediction of an exploration later than every one windowed so far must come
    for node in NODES:
        assert _value(g.ros2_node("param", "get", *CLI, node, "diagnostics_period_s"))
    replay_scene(g, f"/{NAMESPACE}/biotac_driver")
    windowed = [int(n) for n in re.findall(r"\[window_node-\d+\] .*?: exploration (\d+):", g.output())]
    before = max(windowed, default=0)
    deadline = time.monotonic() + FIRST_PREDICTION_S
    latest = before
    while latest <= before:
        assert time.monotonic() < deadline, f"no prediction after exploration {before}:\n{g.output()[-6000:]}"
        try:
            text = g.ros2("topic", "echo", "--once", "--no-daemon", f"/{NAMESPACE}/tactile/prediction",
                          "tactile_descriptors_msgs/msg/Prediction", timeout=CLI_S)
        except subprocess.TimeoutExpired:
            continue
        latest = int(re.search(r"^exploration_id: (\d+)$", text, re.M).group(1))
    for bad in ("Traceback", "process has died"):
        assert bad not in g.output(), g.output()[-4000:]
