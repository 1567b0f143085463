"""Every writable parameter of every node, set to hostile values through the real ``ros2 param set``.

The Shadow Hand graph runs under ``ros2 launch`` on its simulated scene (BioTac driver, window node,
classifier), with a skin driver beside it (``ros2 run``, loopback transport); each writable parameter of each
node (from the node schemas) is set to 0, -1, 2^62, 1e-300, 1e300, nan, +inf, -inf, '', a word and a
100,000-character string.  Every set must be answered -- "Set parameter successful" with the value inside its
declared range, or "Setting parameter failed: <reason>" -- and every node process must live on; a value that
was accepted is set back.  Afterwards every node still answers, and the graph still predicts new explorations.

Each parameter gets ``TACTILE_PARAM_FUZZ_VALUES`` of the 11 values (default 1, in rotation so that together the
23 parameters get every value); set it to 11 for all of them (about 15 minutes on 2 cores).  Every call starts
a DDS participant, six at a time: on a busy machine Fast DDS has left a node unreachable by new participants for
minutes (docs/nodes.md), so the suite makes fewer calls.  A call spins 0.5 s for its node look-up and again for
the call (``--spin-time``); the look-up then waits for the node (``--timeout``) and the call for the services,
each only as long as discovery takes.
``test/params/test_node_schemas.py`` sets all 11 on every parameter of every node in process.

That Fast DDS fault has also hidden one live node from every new participant for minutes, while the rest of
the graph was found (docs/nodes.md).  A value cannot do that (a node a value hung would still be found, its
calls unanswered), so when a call's last try says "Node not found" while the node's process lives, the test
warns with the failure and the node's stacks, takes the remedy docs/nodes.md gives (stop the graph, ``fastdds
shm clean``, start again) and fuzzes the parameters left from where each job stopped.  Once per run: a node
unreachable again fails the test.
"""

from __future__ import annotations

import os
import random
import re
import signal
import subprocess
import time
import warnings
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import NamedTuple

import pytest
import yaml
from dds_shm import clean_zombie_shm
from stacks import native_stacks
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
PER_PARAMETER = max(1, min(len(VALUES), int(os.environ.get("TACTILE_PARAM_FUZZ_VALUES", "1"))))
#: A namespace of this run's own: the machine's other test runs pick random domain ids too, and a graph of
#: theirs in the same domain must not answer for ours (nor mix its frames into ours).
NAMESPACE = f"fuzz_{os.getpid()}_{random.randrange(1 << 30)}"
NODES = {f"/{NAMESPACE}/{exe}": exe for exe in ("biotac_driver", "window_node", "classifier_node", "skin_driver")}
CLI = ("--no-daemon", "--spin-time", "0.5", "--timeout", "30")
#: parallel ``ros2 param`` calls (each mostly waits on discovery)
WORKERS = 6


class FuzzGraph:
    """The Shadow Hand graph under ``ros2 launch`` and a skin driver beside it, in this run's namespace."""

    def __init__(self, tmp: Path) -> None:
        self.tmp = tmp
        self.starts = 0
        self.start()

    def start(self) -> None:
        """Start the graph; return once it has predicted and every node is discovered."""
        self.starts += 1
        tmp = self.tmp / f"start{self.starts}"
        tmp.mkdir()
        # a scene that outlasts the fuzzing on a loaded machine: the graph must still predict afterwards
        # (a file of its own: start_launch writes long_scene's file again)
        doc = yaml.safe_load(long_scene("shadow_hand", tmp).read_text())
        for entry in doc["explorations"]:
            entry["repeat"] = 8 * int(entry.get("repeat", 1))
        scene = tmp / "fuzz_scene.yaml"
        scene.write_text(yaml.safe_dump(doc, sort_keys=False))
        proc, log, env = start_launch("shadow_hand", tmp, f"sim:={scene}", f"namespace:={NAMESPACE}")  # last sim wins
        self.g = Graph("shadow_hand", proc, log, env, tmp / "ros_home", "")
        self.skin_log = open(tmp / "skin.log", "w")
        self.skin = subprocess.Popen([str(BIN / "ros2"), "run", PKG, "skin_driver", "--ros-args", "-r",
                                      f"__ns:=/{NAMESPACE}", "-p", "robot:=nao", "-p", "transport:=loopback"],
                                     stdout=self.skin_log, stderr=subprocess.STDOUT, env=env, start_new_session=True)
        try:
            self.g.first_prediction = self.g.ros2("topic", "echo", "--once", "--no-daemon",
                                                  f"/{NAMESPACE}/tactile/prediction",
                                                  "tactile_descriptors_msgs/msg/Prediction",
                                                  timeout=FIRST_PREDICTION_S)
            self.g.wait_for_nodes(set(NODES))
        except BaseException:
            self.stop()
            raise

    def stop(self) -> None:
        """Ctrl-C to the launch and to the skin driver (SIGKILL to what is left 30 s later)."""
        for p in (self.g.proc, self.skin):
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGINT)
                try:
                    p.wait(timeout=30)
                except subprocess.TimeoutExpired:
                    os.killpg(p.pid, signal.SIGKILL)
                    p.wait()
        self.skin_log.close()

    def restart(self) -> None:
        """The remedy docs/nodes.md gives for a node new participants no longer find: stop the graph, remove
        the shared-memory files no live process holds, start again."""
        self.stop()
        clean_zombie_shm()
        self.start()


@pytest.fixture(scope="module")
def graph(tmp_path_factory) -> Iterator[FuzzGraph]:
    from tactile_descriptors_ros.core.fast import warm_up

    warm_up()
    fg = FuzzGraph(tmp_path_factory.mktemp("param_fuzz"))
    try:
        yield fg
    finally:
        fg.stop()


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


#: The last ``ros2`` try of a call said the node was not there (:meth:`Graph.ros2_node`'s failure message).
_LAST_TRY_NOT_FOUND = re.compile(r"tries: [^\n]*\['Node not found'\]\n")


class Unreachable(NamedTuple):
    """A node new participants stopped finding while its process lived: where its job stopped."""

    node: str
    names: list[str]  # the job's parameters not yet fuzzed (the current one first)
    failure: str


def test_every_writable_parameter_survives_hostile_sets_through_the_cli(graph):
    fg = graph
    pids = _node_pids(fg.g, fg.skin)

    def fuzz(job: tuple[str, list[str]]) -> tuple[list[str], Unreachable | None]:
        node, names = job
        problems: list[str] = []
        for k, name in enumerate(names):
            try:
                problems += fuzz_one(node, name)
            except AssertionError as e:
                # not a value's doing: a value cannot hide a live node from discovery (a node a value hung
                # would still be found, its calls unanswered), a Fast DDS transport fault can (docs/nodes.md)
                if _LAST_TRY_NOT_FOUND.search(str(e)) and _alive(pids[node]):
                    return problems, Unreachable(node, names[k:], str(e))
                raise
        return problems, None

    def fuzz_one(node: str, name: str) -> list[str]:
        g = fg.g
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

    def run(jobs: list[tuple[str, list[str]]]) -> tuple[list[str], list[Unreachable]]:
        with ThreadPoolExecutor(WORKERS) as pool:
            done = list(pool.map(fuzz, jobs))
        return [p for found, _ in done for p in found], [u for _, u in done if u is not None]

    # parameters checked together (one apply hook) are set one after the other: a value accepted for one moves
    # what the others accept; independent ones in parallel
    groups: dict[tuple[str, str], list[str]] = {}
    for node, exe in NODES.items():
        for p in SCHEMAS[exe].tunable():
            groups.setdefault((node, p.apply or p.name), []).append(p.name)
    jobs = [(node, names) for (node, _), names in groups.items()]
    n_parameters = sum(len(names) for _, names in jobs)
    assert n_parameters >= 20
    assert n_parameters * PER_PARAMETER >= len(VALUES)  # together: every value
    order = {(node, name): i for i, (node, name) in enumerate((n, m) for n, names in jobs for m in names)}
    started = time.monotonic()
    problems, unreachable = run(jobs)
    if unreachable:
        # once per run, the remedy: a graph started again, on which the jobs go on where they stopped; a node
        # unreachable again fails the test
        stacks = "".join(f"\n--- stacks of {u.node} (pid {pids[u.node]}):\n{native_stacks(pids[u.node])[-6000:]}"
                         for u in {u.node: u for u in unreachable}.values())
        first_failure = unreachable[0].failure
        warnings.warn(f"new participants stopped finding {sorted({u.node for u in unreachable})} while their "
                      f"processes lived; started the graph again and went on.\n--- the failure:\n"
                      f"{first_failure[:3000]}{stacks}", stacklevel=1)
        fg.restart()
        pids.clear()
        pids.update(_node_pids(fg.g, fg.skin))
        more, again = run([(u.node, u.names) for u in unreachable])
        problems += more + [f"{u.node} unreachable again after the graph was started again:\n{u.failure}"
                            for u in again]
    took = time.monotonic() - started
    g = fg.g
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
