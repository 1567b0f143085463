"""The graph under the real ``ros2 launch`` and driven with the real ``ros2`` CLI, as a user runs it.

For each robot with a simulated scene: ``ros2 launch`` until the first
Prediction, ``ros2 topic echo --once`` on every topic with default QoS,
``ros2 param describe/get/set``, the tare, save and reset services, lifecycle
transitions, the README's label command, and Ctrl-C (every process gone, no
traceback); also Ctrl-C with one window node per body part.

``ros2 launch`` is started the way a terminal starts it: in its own process
group with SIGINT at its default (a background job of a non-interactive shell
would ignore it) and a terminal on stdin (``ros_cli.start_at_a_terminal``), and
Ctrl-C is SIGINT to the whole group: each node gets it from the "terminal",
and ``ros2 launch`` leaves it at that.  Every ``ros2`` verb runs with
``--no-daemon``.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
from ros_cli import CliRun, finish, run_ros2, start_at_a_terminal, without_launchs_ignored_interrupt
from stacks import native_stacks

from tactile_descriptors_ros.core.robot import load_robot
from tactile_descriptors_ros.launching.graph import build_graph

pytestmark = [pytest.mark.ros, pytest.mark.ros2cli, pytest.mark.slow, pytest.mark.timeout(1800)]

PKG = "tactile_descriptors_ros"
SCENES = {"shadow_hand": "demo_shadow_hand", "nao": "demo_nao"}
BIN = Path(sys.prefix) / "bin"
#: Generous bounds for a loaded 2-core machine: they stop a hung test, they measure nothing.
FIRST_PREDICTION_S = 240.0
CLI_S = 60.0
#: How long a verb that looks its node up is asked again while discovery has not yet seen the node.
DISCOVERY_S = 3 * CLI_S
#: ros2 launch escalates a node to SIGTERM this long after SIGINT (its default sigterm_timeout).
SIGTERM_AFTER_S = 5
#: What a ``ros2`` verb says when its own discovery has not yet seen the node or its services: the node
#: lookup (``--timeout``, ``--spin-time``) or the parameter client's fixed 5 s wait for the services.
NOT_YET_DISCOVERED = ("Node not found", "Wait for service timed out")
#: ``ros2 param`` options: a short fixed spin, then a wait for the node (``--timeout``) and for its parameter
#: services (the client's 5 s), each ending when discovery has seen them.  A verb spins ``--spin-time`` twice
#: whatever it finds (its node lookup, then its service call each make a node of their own): against the
#: running NAO graph on an idle machine, a ``param get`` took 8.1-8.9 s at 3 s and 3.1-5.1 s at 0.5 s.
PARAM_CLI = ("--no-daemon", "--spin-time", "0.5", "--timeout", "20")
MSG_TYPES = {"biotac": "tactile_descriptors_msgs/msg/BioTacFrameBatch",
             "skin": "tactile_descriptors_msgs/msg/SkinPartFrames"}


def _ros_env(ros_home: Path) -> dict[str, str]:
    env = dict(os.environ)
    env["PATH"] = f"{BIN}{os.pathsep}{env.get('PATH', '')}"
    env["ROS_HOME"] = str(ros_home)  # the classifier's default model file goes here, not into ~/.ros
    env["PYTHONUNBUFFERED"] = "1"
    return env



@dataclass
class Graph:
    robot: str
    proc: subprocess.Popen
    log: Path
    env: dict[str, str]
    ros_home: Path
    first_prediction: str

    def ros2(self, *args: str, timeout: float = CLI_S, check: bool = True) -> str:
        """Run ``ros2 ARGS``; return its stdout (raise with its output when it fails and ``check``;
        without ``check``, return stdout and stderr together).  A call that overruns ``timeout`` is stopped
        with Ctrl-C (:func:`ros_cli.finish`) and raises :class:`subprocess.TimeoutExpired`."""
        return self._judged(run_ros2(*args, env=self.env, timeout_s=timeout), args, timeout, check)

    def _judged(self, run: CliRun, args: tuple[str, ...], timeout: float, check: bool) -> str:
        """:meth:`ros2`'s verdict on one finished call."""
        if run.stopped:
            raise subprocess.TimeoutExpired(["ros2", *args], timeout, output=run.stdout, stderr=run.stderr)
        if check and run.returncode != 0:
            raise AssertionError(f"ros2 {' '.join(args)} exited {run.returncode}:\n{run.stdout}\n{run.stderr}"
                                 f"\n--- launch log:\n{self.output()[-4000:]}")
        return run.stdout if check else run.text

    def listed(self, verb: str, spin_s: int) -> set[str]:
        """The names ``ros2 VERB list`` shows, for a caller that polls until what it waits for is listed.  A
        CLI process that crashed (:meth:`ros2_node`: seen under load as a segmentation fault in its own
        ``destroy_node``) has listed nothing and says nothing about the graph: it shows no name, and the
        caller's poll asks again within its own deadline.  Any other failure raises as in :meth:`ros2`."""
        args = (verb, "list", "--no-daemon", "--spin-time", str(spin_s))
        run = run_ros2(*args, env=self.env, timeout_s=CLI_S)
        if run.crashed:
            print(f"ros2 {' '.join(args)} crashed (signal {-run.returncode}); asked again")
            return set()
        return set(self._judged(run, args, CLI_S, True).split())

    def output(self) -> str:
        return self.log.read_text(errors="replace")

    def wait_for_output(self, pattern: str) -> None:
        """Until the launch output has a line matching ``pattern`` (polled, bounded)."""
        deadline = time.monotonic() + CLI_S
        while not re.search(pattern, self.output()):
            assert time.monotonic() < deadline, f"no {pattern!r} in the launch output:\n{self.output()[-3000:]}"
            time.sleep(0.2)  # polling the log file: the event is the line appearing

    def ros2_node(self, *args: str, check: bool = True) -> str:
        """``ros2 ARGS`` for a verb that looks its node up per call (``ros2 lifecycle``, ``param``, ``service call``):
        asked again while the CLI's own discovery has not yet seen the node or its services
        (:data:`NOT_YET_DISCOVERED`), which on a loaded machine can take longer than one ``--spin-time``, or
        when one call is not answered within :data:`CLI_S` (a request sent while the CLI's client and the
        node's service are matched one way only is never answered, and the CLI waits for ever), or when the
        CLI process itself crashed (ended by a signal we did not send: seen under load as a segmentation
        fault in the CLI's own ``destroy_node``, before it had sent anything; a crash says nothing about the
        node asked, whose process the callers check themselves); bounded by :data:`DISCOVERY_S`.  Any other
        failure raises at once (without ``check``, stdout and stderr are returned together)."""
        started = time.monotonic()
        deadline = started + DISCOVERY_S
        crashes: list[str] = []
        attempts: list[str] = []  # when each try ended and how: the failure message says what happened before
        while True:
            run = run_ros2(*args, env=self.env, timeout_s=CLI_S)
            code, text = run.returncode, run.text
            attempts.append(f"{time.monotonic() - started:.0f} s: exit {code}, "
                            + ("stopped" if run.stopped else repr(text.strip().splitlines()[-1:])))
            crashed = run.crashed
            if crashed:
                crashes.append(f"ros2 {' '.join(args)[:200]} crashed (signal {-code}):\n{text[-3000:]}")
                print(crashes[-1].splitlines()[0] + "; asked again")
            undiscovered = run.stopped or crashed or any(m in text for m in NOT_YET_DISCOVERED)
            if run.stopped:
                text = f"no answer within {CLI_S:.0f} s, stopped with Ctrl-C; output so far:\n{text}"
            if not undiscovered and (code == 0 or not check):
                return run.stdout if check else text
            if not undiscovered or time.monotonic() > deadline:
                seen = ""
                if "Node not found" in text or "waiting for service" in text:
                    # what the graph held instead, seen by CLIs of their own, and any shared-memory port that a
                    # participant of the launch could not open (docs/nodes.md: a cause of nodes not found)
                    for verb, every in (("node", ["-a"]), ("service", [])):  # service list has no -a
                        listed = run_ros2(verb, "list", *every, "--no-daemon", "--spin-time", "5", env=self.env,
                                          timeout_s=CLI_S)
                        seen += f"\n--- ros2 {verb} list {' '.join(every)}:\n{listed.text}"
                    ports = [line for line in self.output().splitlines() if "init_port" in line]
                    seen += f"\n--- launch log lines on shared-memory ports: {ports[-10:]}"
                    # the asked node's own lines (started, died, its warnings), wherever they are in the log
                    for name in {a.rsplit("/", 1)[-1] for a in args if a.startswith("/") and len(a) > 1}:
                        own = [line for line in self.output().splitlines() if f"[{name}-" in line]
                        seen += f"\n--- launch log lines of {name}: {own[-10:]}"
                raise AssertionError(f"ros2 {' '.join(args)} exited {code}:\n{text}"
                                     + f"\n--- {len(attempts)} tries: " + "; ".join(attempts) + seen
                                     + "".join(f"\n--- earlier: {c}" for c in crashes)
                                     + f"\n--- launch log:\n{self.output()[-4000:]}")

    def wait_for_nodes(self, names: set[str]) -> None:
        """Poll ``ros2 node list`` until every node in ``names`` is discovered."""
        deadline = time.monotonic() + CLI_S
        seen: set[str] = set()
        while time.monotonic() < deadline:
            seen = self.listed("node", 2)
            if names <= seen:
                return
        raise AssertionError(f"nodes {sorted(names - seen)} not discovered; saw {sorted(seen)}")


#: The demo scene played this many times over: the module's tests (tare, labels) need a scene that is
#: still running when they come, and on a loaded machine they come later than the 1.5-minute demo lasts.
SCENE_REPEATS = 5


def long_scene(robot: str, tmp: Path) -> Path:
    """The robot's demo scene with every exploration repeated :data:`SCENE_REPEATS` times as often."""
    import yaml

    from tactile_descriptors_ros.sim.scene import scene_path

    doc = yaml.safe_load(scene_path(SCENES[robot]).read_text())
    for entry in doc["explorations"]:
        entry["repeat"] = SCENE_REPEATS * int(entry.get("repeat", 1))
    doc["scene"]["name"] = f"{doc['scene']['name']}_long"
    path = tmp / f"{SCENES[robot]}_long.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def start_launch(robot: str, tmp: Path, *extra: str) -> tuple[subprocess.Popen, Path, dict[str, str]]:
    """``ros2 launch tactile_descriptors_ros <robot>.launch.py sim:=<scene> EXTRA`` in its own process group."""
    tmp.mkdir(parents=True, exist_ok=True)
    env = _ros_env(tmp / "ros_home")
    log = tmp / "launch.log"
    scene = long_scene(robot, tmp)
    proc = start_at_a_terminal([str(BIN / "ros2"), "launch", PKG, f"{robot}.launch.py", f"sim:={scene}", *extra],
                               log, env=env)
    return proc, log, env


def node_processes(proc: subprocess.Popen) -> list:
    import psutil

    return [psutil.Process(proc.pid), *psutil.Process(proc.pid).children(recursive=True)]


def ctrl_c(proc: subprocess.Popen, log: Path) -> tuple[list, str]:
    """SIGINT to the launch's process group (a terminal's Ctrl-C); return processes still alive and the log."""
    import psutil

    procs = node_processes(proc)
    assert len(procs) > 1, "ros2 launch started no nodes"
    os.killpg(proc.pid, signal.SIGINT)
    # A node still running after ros2 launch escalated it to SIGTERM is stuck: its stacks say where.
    _, late = psutil.wait_procs(procs, timeout=SIGTERM_AFTER_S + 2)
    stacks = [f"\nstacks of {p.pid} {_cmdline(p)}:\n{native_stacks(p.pid)}" for p in late if p.pid != proc.pid]
    _, alive = psutil.wait_procs(late, timeout=3 * SIGTERM_AFTER_S)
    proc.wait(timeout=10)
    return alive, log.read_text(errors="replace") + "".join(stacks)


def _cmdline(p) -> str:
    try:
        return " ".join(p.cmdline()[:2])
    except Exception:  # noqa: BLE001 - it ended meanwhile
        return "(ended)"


def assert_clean_shutdown(alive: list, text: str, executables: list[str]) -> None:
    assert not alive, f"still running after Ctrl-C: {alive}\n{text[-3000:]}"
    # A node that did not end on SIGINT within SIGTERM_AFTER_S is escalated and logged so.
    assert "escalating to 'SIGTERM'" not in text and "escalating to 'SIGKILL'" not in text, text[-20000:]
    # At a terminal ros2 launch signals no node itself: the terminal's SIGINT reached them all.
    assert "sending signal 'SIGINT'" not in text, text[-4000:]
    nodes_text = without_launchs_ignored_interrupt(text)
    # "Exception in '...' callback": the events executor's log of a callback that raised
    for bad in ("Traceback", "RCLError", "KeyboardInterrupt", "process has died", "Exception in '"):
        assert bad not in nodes_text, f"{bad!r} in the launch output:\n{text[-4000:]}"
    # ros2 launch names a process <executable>-<n>
    finished = sorted(re.findall(r"\[INFO\] \[(\w+)-\d+\]: process has finished cleanly", text))
    assert finished == sorted(executables), f"finished cleanly: {finished}, expected {sorted(executables)}"


@pytest.fixture(scope="module", autouse=True)
def compiled_kernel():
    """The descriptor kernel compiled into its cache before any node starts (as make setup does)."""
    from tactile_descriptors_ros.core.fast import warm_up

    warm_up()


@pytest.fixture(scope="module", params=sorted(SCENES))
def graph(request, tmp_path_factory) -> Iterator[Graph]:
    robot = request.param
    tmp = tmp_path_factory.mktemp(f"launch_{robot}")
    proc, log, env = start_launch(robot, tmp)
    g = Graph(robot, proc, log, env, tmp / "ros_home", "")
    try:
        # The type is given so that echo waits for the publisher instead of failing on an unknown topic.
        g.first_prediction = g.ros2("topic", "echo", "--once", "--no-daemon", "/tactile/prediction",
                                    "tactile_descriptors_msgs/msg/Prediction", timeout=FIRST_PREDICTION_S)
        g.wait_for_nodes({f"/{s.name}" for s in build_graph(robot, sim_scene=SCENES[robot])})
        yield g
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGINT)
            try:
                proc.wait(timeout=4 * SIGTERM_AFTER_S)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()


#: What ``ros2 launch`` printed when a test's Ctrl-C landed in a weak reference's callback of its own.
LAUNCHS_IGNORED_INTERRUPT = """\
[tf_publisher-3] [DEBUG] [1796234660.009] [rcl]: Node finalized
Exception ignored in: <function WeakSet.__init__.<locals>._remove at 0x7f4a5d9145e0>
Traceback (most recent call last):
  File "/usr/lib/python3.11/_weakrefset.py", line 39, in _remove
    def _remove(item, selfref=ref(self)):

KeyboardInterrupt: \n[WARNING] [launch]: user interrupted with ctrl-c (SIGINT)
"""


@pytest.mark.parametrize("kept", [
    # a node's traceback: prefixed with its name, as all a node prints
    "[window_node-1] Traceback (most recent call last):\n[window_node-1]   File \"x.py\", line 1, in f\n"
    "[window_node-1] KeyboardInterrupt\n",
    # an ignored exception of the launch process that is not the interrupt
    "Exception ignored in: <function f at 0x1>\nTraceback (most recent call last):\n  File \"x.py\", line 1, in f\n"
    "RuntimeError: x\n",
])
def test_only_the_launchs_own_ignored_interrupt_is_left_out_of_its_output(kept):
    assert "Traceback" not in without_launchs_ignored_interrupt(LAUNCHS_IGNORED_INTERRUPT)
    assert without_launchs_ignored_interrupt(LAUNCHS_IGNORED_INTERRUPT).splitlines() == [
        LAUNCHS_IGNORED_INTERRUPT.splitlines()[0], LAUNCHS_IGNORED_INTERRUPT.splitlines()[-1]]
    assert without_launchs_ignored_interrupt(LAUNCHS_IGNORED_INTERRUPT + kept) == (
        without_launchs_ignored_interrupt(LAUNCHS_IGNORED_INTERRUPT) + kept)


def test_a_cli_call_that_crashed_is_asked_again_and_any_other_failure_is_not(monkeypatch, tmp_path):
    """``Graph.ros2_node``: a CLI process ended by a signal it was not sent (a crash in its own teardown) is
    asked again; a CLI that answered with a failure is not."""
    log = tmp_path / "launch.log"
    log.write_text("")
    g = Graph("nao", None, log, {}, tmp_path, "")
    crash = CliRun(-11, "", "Fatal Python error: Segmentation fault", stopped=False)
    runs = iter([crash, CliRun(0, "Set parameter successful\n", "", stopped=False)])
    monkeypatch.setattr(sys.modules[__name__], "run_ros2", lambda *a, **k: next(runs))
    assert g.ros2_node("param", "set", "/n", "p", "1") == "Set parameter successful\n"
    runs = iter([CliRun(1, "", "Parameter not set", stopped=False), CliRun(0, "late", "", stopped=False)])
    with pytest.raises(AssertionError, match="exited 1"):
        g.ros2_node("param", "set", "/n", "p", "1")


def test_a_list_that_crashed_shows_no_name_and_a_poll_asks_again(monkeypatch, tmp_path):
    """``Graph.listed``: a ``ros2 ... list`` ended by a signal it was not sent shows nothing and the poll that
    asked (``wait_for_nodes``) asks again; a list that failed otherwise raises."""
    log = tmp_path / "launch.log"
    log.write_text("")
    g = Graph("nao", None, log, {}, tmp_path, "")
    crash = CliRun(-11, "", "Fatal Python error: Segmentation fault", stopped=False)
    calls: list[tuple] = []

    def run(*args, **kwargs):
        calls.append(args)
        return next(runs)

    monkeypatch.setattr(sys.modules[__name__], "run_ros2", run)
    runs = iter([crash, CliRun(0, "/a\n/b\n", "", stopped=False)])
    g.wait_for_nodes({"/a", "/b"})
    assert calls == [("node", "list", "--no-daemon", "--spin-time", "2")] * 2
    runs = iter([crash])
    assert g.listed("topic", 3) == set()
    runs = iter([CliRun(1, "", "rcl error", stopped=False)])
    with pytest.raises(AssertionError, match="exited 1"):
        g.listed("topic", 3)


def test_launch_reaches_first_prediction(graph):
    assert re.search(r"^exploration_id: [1-9]\d*$", graph.first_prediction, re.M), graph.first_prediction
    assert graph.proc.poll() is None


def test_every_launched_node_takes_the_shipped_dds_profile(graph):
    """ros2 launch gives each node the package's Fast DDS profile (config/fastdds.xml; see test_dds_profile.py)."""
    import psutil

    from tactile_descriptors_ros.launching.graph import unrunnable
    from tactile_descriptors_ros.launching.processes import DDS_PROFILE, DDS_PROFILE_VARIABLES

    specs = build_graph(graph.robot, sim_scene=SCENES[graph.robot])
    left_out = unrunnable(specs)
    names = {s.executable for s in specs if s.package == PKG and s.name not in left_out}
    nodes = {}
    for proc in node_processes(graph.proc)[1:]:
        try:
            argv, environ = proc.cmdline(), proc.environ()
        except psutil.Error:  # a helper process that ended meanwhile
            continue
        exe = next((n for n in names if any(os.path.basename(a) == n for a in argv)), None)
        if exe is not None:
            nodes[proc.pid] = (exe, {k: environ.get(k, "") for k in DDS_PROFILE_VARIABLES})
    assert {exe for exe, _ in nodes.values()} == names, nodes
    for exe, env in nodes.values():
        assert set(env.values()) == {env["FASTDDS_DEFAULT_PROFILES_FILE"]}, (exe, env)
        profile = Path(env["FASTDDS_DEFAULT_PROFILES_FILE"])
        assert profile.name == DDS_PROFILE and "<segment_size>2097152</segment_size>" in profile.read_text()


def _topics(robot: str) -> dict[str, str]:
    """Every topic the graph publishes -> its type (frames of each body part, descriptor, prediction, diagnostics)."""
    from tactile_descriptors_ros.nodes.conversions import message_kind

    desc = load_robot(robot)
    topics = {f"/tactile/{p.name}/frames": MSG_TYPES[message_kind(desc.cell_types[p.cell_type])]
              for p in desc.body_parts}
    topics.update({"/tactile/descriptor": "tactile_descriptors_msgs/msg/Descriptor",
                   "/tactile/prediction": "tactile_descriptors_msgs/msg/Prediction",
                   "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray"})
    return topics


#: How many ``ros2 topic echo`` participants start at once: many participants starting together on a busy
#: machine can fail to open their shared-memory ports and then not find each other (docs/nodes.md).
ECHOES_AT_ONCE = 3


def test_every_topic_echoes_once_with_default_qos(graph):
    topics = _topics(graph.robot)
    failed, stopped = {}, []
    names = list(topics)
    for start in range(0, len(names), ECHOES_AT_ONCE):
        _echo_once(graph, {t: topics[t] for t in names[start:start + ECHOES_AT_ONCE]}, failed, stopped)
    assert not failed, failed
    if stopped:
        print(f"ros2 topic echo --once did not exit after echoing, stopped with Ctrl-C: {stopped}")
    # every topic listed: asked again while the CLI's discovery (one spin each time) has not seen them all
    deadline = time.monotonic() + CLI_S
    listed: set[str] = set()
    while not set(topics) <= listed and time.monotonic() < deadline:
        listed = graph.listed("topic", 3)
    assert set(topics) <= listed, f"not listed: {sorted(set(topics) - listed)}"


def _echo_once(graph: Graph, topics: dict[str, str], failed: dict, stopped: list[str]) -> None:
    """``ros2 topic echo --once`` each of ``topics`` (name -> type), all at once; a topic that echoed nothing
    goes into ``failed``, one whose CLI hung after echoing into ``stopped``."""
    echoes = {t: subprocess.Popen([str(BIN / "ros2"), "topic", "echo", "--once", "--no-daemon", "--no-arr", t, ty],
                                  env=graph.env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
              for t, ty in topics.items()}
    for topic, p in echoes.items():
        # A CLI process that printed its message and then hung on its way out (its own DDS teardown: seen once,
        # on Jazzy, in CI) has still echoed the topic: stopped with Ctrl-C, its status is not judged.
        run = finish(p, FIRST_PREDICTION_S)
        if run.crashed:
            # the CLI ended by a signal we did not send, before printing anything (seen once at load 5: SIGKILL,
            # no output, no OOM kill): as in Graph.ros2_node, a crashed CLI says nothing about the topic; ask again
            print(f"ros2 topic echo {topic} ended by signal {-run.returncode} with {len(run.stdout)} characters "
                  "out; asked again")
            run = run_ros2("topic", "echo", "--once", "--no-daemon", "--no-arr", topic, topics[topic],
                           env=graph.env, timeout_s=FIRST_PREDICTION_S)
        if run.stopped:
            stopped.append(topic)
        if (run.returncode != 0 and not run.stopped) or not run.stdout.rstrip().endswith("---"):
            failed[topic] = (run.returncode, run.stdout[-300:], run.stderr[-300:])


def test_param_set_validated(graph):
    args = PARAM_CLI
    assert "Set parameter successful" in graph.ros2_node("param", "set", *args, "/classifier_node", "eta", "0.5")
    assert graph.ros2_node("param", "get", *args, "/classifier_node", "eta").strip() == "Double value is: 0.5"
    refused = graph.ros2_node("param", "set", *args, "/classifier_node", "eta", "-1.0", check=False)
    assert "Setting parameter failed" in refused, refused
    assert graph.ros2_node("param", "get", *args, "/classifier_node", "eta").strip() == "Double value is: 0.5"


def test_param_describe_get(graph):
    window = "/window_node"
    text = graph.ros2_node("param", "describe", *PARAM_CLI, window, "window.length_s")
    assert "Type: double" in text, text
    # the range travels in the ParameterDescriptor, so the CLI shows it; a tunable value says no "Read only"
    assert re.search(r"^ +Min value: 0\.001$", text, re.M), text
    assert "Read only" not in text, text
    mode = graph.ros2_node("param", "describe", *PARAM_CLI, window, "window.mode")
    assert "Read only: true" in mode and "Additional constraints: one of: fixed, exploration" in mode, mode
    value = graph.ros2_node("param", "get", *PARAM_CLI, "/classifier_node", "eta")
    assert re.match(r"Double value is: \d", value), value
    robot = graph.ros2_node("param", "get", *PARAM_CLI, window, "robot")
    assert re.match(rf"String value is: \S*\b{graph.robot}(\.yaml)?$", robot.strip()), robot


def _readme_label_command(repo_dir: Path) -> str:
    lines = [line for line in (repo_dir / "README.md").read_text().splitlines()
             if line.startswith("ros2 service call /classifier_node/label ")]
    assert len(lines) == 1, lines
    return lines[0]


def _trigger(graph: Graph, service: str) -> tuple[bool, str]:
    text = graph.ros2_node("service", "call", service, "std_srvs/srv/Trigger")
    m = re.search(r"Trigger_Response\(success=(True|False), message='(.*)'\)", text)
    assert m, text
    return m.group(1) == "True", m.group(2)


def test_readme_label_command_teaches_the_classifier(graph, repo_dir):
    assert "has_model: false" in graph.first_prediction  # a fresh ROS_HOME: no model yet
    # the ~/label service answers once the label is learned and saved: no log to poll, no race with discovery
    # (`ros2 service call` waits for the service)
    out = subprocess.run(["bash", "-c", _readme_label_command(repo_dir)], env=graph.env, check=True,
                         timeout=DISCOVERY_S, capture_output=True, text=True).stdout
    assert "success=True, saved=True, outcome='learned'" in out and "class_name='cork'" in out, out
    graph.wait_for_output(r"\[classifier_node\]: learned exploration \d+: 'cork'")
    ok, message = _trigger(graph, "/classifier_node/save")
    assert ok, message
    assert re.search(r"saved 1 class", message), message
    model = Path(message.rsplit(" to ", 1)[1])
    assert model.is_relative_to(graph.ros_home), message  # the default model file lives under $ROS_HOME
    assert model.is_file() and '"cork"' in model.read_text()


def replay_scene(graph: Graph, driver: str) -> None:
    """Play the simulated scene again: the driver's lifecycle cleanup and configure reopen the simulated transport.

    The transitions go through the driver's ``change_state`` service, which ``ros2 service call`` waits for;
    ``ros2 lifecycle set`` first looks the node's name up in the graph, and once, in CI, after hundreds of CLI
    participants, that look-up said "Node not found" for minutes (``test_driver_lifecycle_transitions`` tests
    ``ros2 lifecycle set`` itself).  Returns once a frames message of the new play has arrived."""
    for transition in ("deactivate", "cleanup", "configure", "activate"):
        out = graph.ros2_node("service", "call", f"{driver}/change_state", "lifecycle_msgs/srv/ChangeState",
                              f"{{transition: {{label: {transition}}}}}")
        assert "ChangeState_Response(success=True)" in out, f"{transition}: {out}"
    topic, msg_type = next((t, ty) for t, ty in _topics(graph.robot).items() if t.endswith("/frames"))
    namespace = driver.rsplit("/", 1)[0]
    graph.ros2("topic", "echo", "--once", "--no-daemon", "--no-arr", f"{namespace}{topic}", msg_type,
               timeout=FIRST_PREDICTION_S)


def test_tare_save_reset_services(graph):
    driver = "/biotac_driver" if graph.robot == "shadow_hand" else "/skin_driver"
    ok, message = _trigger(graph, f"{driver}/tare")
    if "the simulated scene has ended" in message:
        # the module's tests outlasted the long scene on a loaded machine (seen at load 5): the driver is right
        # to refuse, and the tare is asked again on a scene playing
        print(f"tare: {message}; scene played again")
        replay_scene(graph, driver)
        ok, message = _trigger(graph, f"{driver}/tare")
    # The scene is running, so the frames are current: the tare either succeeds or is refused because a sensor
    # is touched at that moment, and the driver says which.
    assert "stale" not in message, message
    assert message, "tare answered with no message"
    if not ok:
        assert message.startswith("refused: ") and "in contact" in message, message
    ok, message = _trigger(graph, "/classifier_node/reset")  # erases the model: off unless enabled
    assert not ok and "enable_reset:=true" in message, message
    ok, message = _trigger(graph, "/classifier_node/save")
    assert ok and "saved" in message, message


def test_driver_lifecycle_transitions(graph):
    driver = "/biotac_driver" if graph.robot == "shadow_hand" else "/skin_driver"
    lifecycle = ("lifecycle",)

    def state() -> str:
        return graph.ros2_node(*lifecycle, "get", "--no-daemon", "--spin-time", "3", driver).split()[0]

    assert state() == "active"
    assert "Transitioning successful" in graph.ros2_node(*lifecycle, "set", "--no-daemon", "--spin-time", "3",
                                                         driver, "deactivate")
    assert state() == "inactive"
    assert "Transitioning successful" in graph.ros2_node(*lifecycle, "set", "--no-daemon", "--spin-time", "3",
                                                         driver, "activate")
    assert state() == "active"


def test_ctrl_c_stops_every_process_cleanly(graph):
    executables = [s.executable for s in build_graph(graph.robot, sim_scene=SCENES[graph.robot])]
    alive, text = ctrl_c(graph.proc, graph.log)
    assert_clean_shutdown(alive, text, executables)


def test_ctrl_c_with_split_window_nodes(tmp_path):
    robot = "shadow_hand"
    proc, log, env = start_launch(robot, tmp_path, "split_window_nodes:=true")
    specs = build_graph(robot, sim_scene=SCENES[robot], split_window_nodes=True)
    g = Graph(robot, proc, log, env, tmp_path / "ros_home", "")
    try:
        g.ros2("topic", "echo", "--once", "--no-daemon", "--no-arr", "/tactile/descriptor",
               "tactile_descriptors_msgs/msg/Descriptor", timeout=FIRST_PREDICTION_S)
        g.wait_for_nodes({f"/{s.name}" for s in specs})
        alive, text = ctrl_c(proc, log)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert_clean_shutdown(alive, text, [s.executable for s in specs])


# ------------------------------------------------------------------ launch arguments and node deaths
def _launch_until_it_ends(*args: str, env: dict[str, str], log: Path, timeout_s: float) -> tuple[int, str]:
    """``ros2 launch ARGS`` run until it ends on its own (a bound, not a wait: a launch still running at the
    bound is killed and fails the test); return its exit code and output."""
    proc = start_at_a_terminal([str(BIN / "ros2"), "launch", PKG, *args], log, env=env)
    try:
        code = proc.wait(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGINT)
        try:
            proc.wait(timeout=4 * SIGTERM_AFTER_S)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
        raise AssertionError(f"ros2 launch {' '.join(args)} still running after {timeout_s:.0f} s:\n"
                             f"{log.read_text()[-3000:]}") from None
    return code, log.read_text(errors="replace")


@pytest.mark.parametrize("argument, says", [
    ("model_pth:=/tmp/model.json", r"'model_pth': unknown launch argument; did you mean model_path\? \(valid: robot, "),
    ("split_window_nodes:=yes_please", r"'split_window_nodes': must be true or false, got 'yes_please'"),
])
def test_a_bad_launch_argument_ends_the_launch_naming_what_is_valid(tmp_path, argument, says):
    code, text = _launch_until_it_ends("shadow_hand.launch.py", argument, env=_ros_env(tmp_path / "ros_home"),
                                       log=tmp_path / "launch.log", timeout_s=CLI_S)
    assert code != 0 and re.search(says, text), text[-3000:]
    assert "process started" not in text, text[-3000:]  # nothing was started


def test_a_node_that_dies_ends_the_launch_with_its_name_and_exit_code(tmp_path):
    """Without a scene the BioTac driver cannot open its Cheetah adapter (none here) and exits 2: the launch
    says so, stops every other node and ends with code 1.  Every other node finishes cleanly, also one still
    importing its module when the stop comes (no ``KeyboardInterrupt``)."""
    code, text = _launch_until_it_ends("shadow_hand.launch.py", env=_ros_env(tmp_path / "ros_home"),
                                       log=tmp_path / "launch.log", timeout_s=FIRST_PREDICTION_S)
    assert code == 1, text[-3000:]
    assert re.search(r"node biotac_driver exited with code 2: stopping the launch", text), text[-3000:]
    assert re.search(r"\[FATAL\] \[[\d.]+\] \[biotac_driver\]: ", text), text[-3000:]
    finished = set(re.findall(r"\[INFO\] \[(\w+)-\d+\]: process has finished cleanly", text))
    assert finished == {"classifier_node", "window_node", "contact_node", "tf_publisher"}, text[-3000:]
    assert "KeyboardInterrupt" not in text and "Traceback" not in text, text[-3000:]


def _frames_bag(path: Path, explorations: int = 3) -> Path:
    """A bag of one finger's BioTac frames: ``explorations`` touches of 2.5 s and their releases."""
    from node_helpers import BiotacStream
    from rclpy.serialization import serialize_message

    from tactile_descriptors_ros.bags.io import BagWriter

    stream = BiotacStream()
    topic = "/tactile/index/frames"
    with BagWriter(path) as bag:
        bag.add_topic(topic, "tactile_descriptors_msgs/msg/BioTacFrameBatch")
        for k in range(explorations):
            for msg in stream.exploration(40.0 + 80.0 * k):
                stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
                bag.write(topic, stamp, serialize_message(msg))
    return path


def test_without_drivers_a_replayed_bag_is_windowed_and_predicted(tmp_path):
    """drivers:=false starts every node but the drivers; tactile replay plays frames into them; the
    params_file and log_level arguments reach the nodes."""
    import yaml

    bag = _frames_bag(tmp_path / "frames")
    params = tmp_path / "params.yaml"
    params.write_text(yaml.safe_dump({
        "classifier_node": {"ros__parameters": {"eta": 0.25}},
        "window_node": {"ros__parameters": {"body_parts": ["index"], "qos": {"frames": {"reliability": "reliable"}}}},
    }))
    env = _ros_env(tmp_path / "ros_home")
    log = tmp_path / "launch.log"
    proc = start_at_a_terminal([str(BIN / "ros2"), "launch", PKG, "shadow_hand.launch.py", "drivers:=false",
                                f"params_file:={params}", "log_level:=debug"], log, env=env)
    g = Graph("shadow_hand", proc, log, env, tmp_path / "ros_home", "")
    replay = None
    try:
        g.wait_for_nodes({"/window_node", "/classifier_node"})
        commands = " ".join(" ".join(p.cmdline()) for p in node_processes(proc)[1:])
        assert "biotac_driver" not in commands and "window_node" in commands, commands
        replay = subprocess.Popen([str(BIN / "tactile"), "replay", str(bag), "--loop", "--wait-for-subscribers",
                                   str(CLI_S)], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                  start_new_session=True)
        prediction = g.ros2("topic", "echo", "--once", "--no-daemon", "/tactile/prediction",
                            "tactile_descriptors_msgs/msg/Prediction", timeout=FIRST_PREDICTION_S)
        assert re.search(r"^exploration_id: [1-9]\d*$", prediction, re.M), prediction
        eta = g.ros2_node("param", "get", *PARAM_CLI, "/classifier_node", "eta")
        assert eta.strip() == "Double value is: 0.25", eta
        assert re.search(r"^\[window_node-\d+\] \[DEBUG\] ", g.output(), re.M), g.output()[-3000:]
        alive, text = ctrl_c(proc, log)
    finally:
        if replay is not None and replay.poll() is None:
            os.killpg(replay.pid, signal.SIGINT)
            replay.wait(timeout=CLI_S)
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert_clean_shutdown(alive, text, ["window_node", "classifier_node", "tf_publisher", "contact_node"])
