"""Start a node graph as subprocesses, forward their output, stop them cleanly.

What ``ros2 launch`` does for the package's own nodes, on a machine without
``launch``/``launch_ros`` (not on PyPI).  Each
:class:`~.graph.NodeSpec` becomes one process::

    <python> -m tactile_descriptors_ros.nodes.<executable> --ros-args
        -r __node:=<name> [-r __ns:=/<namespace>] --params-file <tmp yaml> [--log-level L] [-r from:=to ...]

started with this interpreter (the venv's own python: the ROS wheels'
bootstrapper has set the library paths of this process, and children
started with another interpreter would not find the ROS libraries).  Each
child runs in its own session, so a Ctrl-C in the terminal reaches only the
launcher, which then stops the children in order: SIGINT to each (rclpy
shuts down cleanly: devices closed, models saved), a wait, then SIGTERM and
finally SIGKILL, always by PID.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO

from ..core.yamlreader import config_dir
from ..errors import ConfigError
from .graph import PACKAGE, NodeSpec, unrunnable, write_parameters_file
from .signals import SignalStop, stop_on_signals

__all__ = ["node_command", "RunningNode", "GraphProcesses", "localhost_environment", "dds_environment",
           "DDS_PROFILE", "DDS_PROFILE_VARIABLES", "run_until_interrupted"]

#: The Fast DDS profile the graph's nodes take (in the config directory): a larger shared-memory segment.
DDS_PROFILE = "fastdds.xml"
#: Where Fast DDS looks for a profile file: 3.x (Kilted) and 2.x (Jazzy).
DDS_PROFILE_VARIABLES = ("FASTDDS_DEFAULT_PROFILES_FILE", "FASTRTPS_DEFAULT_PROFILES_FILE")
_FAST_DDS_RMWS = ("rmw_fastrtps_cpp", "rmw_fastrtps_dynamic_cpp")


def localhost_environment(env: Mapping[str, str] | None = None) -> dict[str, str]:
    """The environment with DDS discovery kept on this machine unless the caller chose otherwise.

    ``ROS_AUTOMATIC_DISCOVERY_RANGE`` defaults to ``LOCALHOST`` (Kilted ignores
    ``ROS_LOCALHOST_ONLY``); set it to ``SUBNET`` yourself for a multi-machine
    robot.  ``ROS_DOMAIN_ID`` is left as it is (0 by default in ROS 2).
    """
    out = dict(os.environ if env is None else env)
    out.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    return out


def dds_environment(env: Mapping[str, str] | None = None) -> dict[str, str]:
    """The variables that give the graph's nodes the shipped Fast DDS profile (``config/fastdds.xml``).

    The profile keeps Fast DDS's transports and gives each participant a
    2 MiB shared-memory segment instead of 512 KiB, which a best-effort
    reader of large body-part messages otherwise loses messages to (the
    file says what was measured).  Empty when ``env`` (the process's
    environment by default) names a profile already (a user's own profile
    wins) or another middleware than Fast DDS in ``RMW_IMPLEMENTATION``.
    """
    env = os.environ if env is None else env
    if (env.get("RMW_IMPLEMENTATION") or "rmw_fastrtps_cpp") not in _FAST_DDS_RMWS:  # Fast DDS: ROS 2's default
        return {}
    if any(env.get(name) for name in DDS_PROFILE_VARIABLES):
        return {}
    path = os.fspath(config_dir() / DDS_PROFILE)
    return dict.fromkeys(DDS_PROFILE_VARIABLES, path)


def node_command(spec: NodeSpec, params_file: str | os.PathLike[str], python: str | None = None) -> list[str]:
    """The command line that starts one node with its name, namespace, parameters and remappings."""
    if spec.package != PACKAGE:
        raise ConfigError(f"the in-repo launcher starts only {PACKAGE} nodes, not {spec.package}/{spec.executable}")
    cmd = [python or sys.executable, "-m", f"{PACKAGE}.nodes.{spec.executable}", "--ros-args",
           "-r", f"__node:={spec.name}"]
    ns = spec.namespace.strip("/")
    if ns:
        cmd += ["-r", f"__ns:=/{ns}"]
    cmd += ["--params-file", os.fspath(params_file)]
    if spec.log_level:
        cmd += ["--log-level", spec.log_level]
    for src, dst in spec.remappings:
        cmd += ["-r", f"{src}:={dst}"]
    return cmd


@dataclass
class RunningNode:
    """A started node process."""

    spec: NodeSpec
    process: subprocess.Popen
    reader: threading.Thread | None = None
    lines: list[str] = field(default_factory=list)

    @property
    def returncode(self) -> int | None:
        return self.process.poll()


class GraphProcesses:
    """Run NodeSpecs as child processes.

    Parameters
    ----------
    specs : sequence of NodeSpec
    env : mapping, optional
        Environment of the children (default: this process's).
    output : file, optional
        Where the children's lines go, each prefixed with ``[node name]``
        (default ``sys.stdout``); ``None`` keeps them only in ``lines``.
    keep_lines : int
        Lines kept per node (for error reports and tests).
    workdir : path, optional
        Where the parameters file is written (default: a temporary folder
        removed by :meth:`stop`).
    prefix : mapping, optional
        Node name -> command words put before its command line: where the
        node runs, e.g. ``["ip", "netns", "exec", "host1"]`` starts it in a
        network namespace (the prefix must exec the command, so the process
        id stays the node's and signals reach it).
    node_env : mapping, optional
        Node name -> environment variables set for that node only (over ``env``).
    """

    def __init__(self, specs: Sequence[NodeSpec], *, env: Mapping[str, str] | None = None,
                 output: IO[str] | None = sys.stdout, keep_lines: int = 200,
                 workdir: str | os.PathLike[str] | None = None,
                 prefix: Mapping[str, Sequence[str]] | None = None,
                 node_env: Mapping[str, Mapping[str, str]] | None = None) -> None:
        if not specs:
            raise ConfigError("no nodes to start")
        names = {s.name for s in specs}
        unknown = sorted((set(prefix or {}) | set(node_env or {})) - names)
        if unknown:
            raise ConfigError(f"no node named {unknown[0]!r} to place (nodes: {', '.join(sorted(names))})")
        self.prefix = {k: list(v) for k, v in (prefix or {}).items()}
        self.node_env = {k: dict(v) for k, v in (node_env or {}).items()}
        #: node name -> why it is not started (:func:`~.graph.unrunnable`); said at :meth:`start` on ``output``
        #: (on stderr when ``output`` is None)
        self.left_out = unrunnable(specs)
        self.specs = [s for s in specs if s.name not in self.left_out]
        if not self.specs:
            raise ConfigError("no node can start here: " + "; ".join(self.left_out.values()))
        self.env = dict(os.environ if env is None else env)
        self.env.update(dds_environment(self.env))
        self.env.setdefault("PYTHONUNBUFFERED", "1")
        self.env.setdefault("RCUTILS_LOGGING_BUFFERED_STREAM", "1")
        self.env.setdefault("RCUTILS_COLORIZED_OUTPUT", "0")
        self.output = output
        self.keep_lines = int(keep_lines)
        self._tmp = None if workdir is not None else tempfile.TemporaryDirectory(prefix="tactile_launch_")
        self.workdir = Path(workdir if workdir is not None else self._tmp.name)
        self.params_file = self.workdir / "parameters.yaml"
        self.nodes: list[RunningNode] = []
        #: names of the nodes that ended on their own (before :meth:`stop`), in order
        self.died: list[str] = []
        self._lock = threading.Lock()

    # ----------------------------------------------------------------- start
    def start(self) -> None:
        """Write the parameters file and start every node."""
        write_parameters_file(self.specs, self.params_file)
        for reason in self.left_out.values():  # said even when the nodes' lines are kept quiet
            print(f"[launch] {reason}", file=self.output if self.output is not None else sys.stderr, flush=True)
        width = max(len(s.name) for s in self.specs)
        for spec in self.specs:
            cmd = [*self.prefix.get(spec.name, []), *node_command(spec, self.params_file)]
            env = {**self.env, **self.node_env.get(spec.name, {})}
            proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE,
                                    stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, text=True, bufsize=1,
                                    start_new_session=True)
            node = RunningNode(spec, proc)
            node.reader = threading.Thread(target=self._forward, args=(node, f"[{spec.name:<{width}}] "),
                                           daemon=True, name=f"out-{spec.name}")
            node.reader.start()
            self.nodes.append(node)

    def _forward(self, node: RunningNode, prefix: str) -> None:
        assert node.process.stdout is not None
        for line in node.process.stdout:
            line = line.rstrip("\n")
            with self._lock:
                node.lines.append(line)
                del node.lines[:-self.keep_lines]
                if self.output is not None:
                    self.output.write(prefix + line + "\n")
                    self.output.flush()

    # ------------------------------------------------------------ supervise
    def exited(self) -> list[RunningNode]:
        """Nodes whose process has ended."""
        return [n for n in self.nodes if n.returncode is not None]

    def wait(self, timeout_s: float | None = None, poll_s: float = 0.2,
             stop: threading.Event | SignalStop | None = None) -> list[RunningNode]:
        """Block until a node exits (returned), ``timeout_s`` passes or ``stop`` is set (``[]``)."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        stop = stop if stop is not None else threading.Event()
        while True:
            done = self.exited()
            if done:
                return done
            if stop.is_set() or (deadline is not None and time.monotonic() >= deadline):
                return []
            stop.wait(poll_s if deadline is None else max(0.0, min(poll_s, deadline - time.monotonic())))

    # ----------------------------------------------------------------- stop
    def stop(self, sigint_timeout_s: float = 10.0, sigterm_timeout_s: float = 3.0) -> dict[str, int | None]:
        """Stop every node: SIGINT, wait; SIGTERM, wait; SIGKILL -- each by PID.

        Returns
        -------
        dict
            Node name -> exit code.
        """
        for sig, timeout in ((signal.SIGINT, sigint_timeout_s), (signal.SIGTERM, sigterm_timeout_s),
                             (signal.SIGKILL, 5.0)):
            alive = [n for n in self.nodes if n.returncode is None]
            if not alive:
                break
            for n in alive:
                try:
                    os.kill(n.process.pid, sig)
                except ProcessLookupError:
                    pass
            deadline = time.monotonic() + timeout
            for n in alive:
                try:
                    n.process.wait(max(0.0, deadline - time.monotonic()))
                except subprocess.TimeoutExpired:
                    pass
        for n in self.nodes:
            if n.reader is not None:
                n.reader.join(timeout=2.0)
            if n.process.stdout is not None:
                n.process.stdout.close()
        if self._tmp is not None:
            self._tmp.cleanup()
            self._tmp = None
        return {n.spec.name: n.returncode for n in self.nodes}

    def __enter__(self) -> GraphProcesses:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


def run_until_interrupted(procs: GraphProcesses, duration_s: float | None = None,
                          stop_when_one_exits: bool = True) -> dict[str, int | None]:
    """Start ``procs`` and supervise them until Ctrl-C, SIGTERM or ``duration_s``; then stop them.

    A node that exits on its own is reported on stderr (its name and exit
    code) and recorded in ``procs.died``; with ``stop_when_one_exits`` (the
    default: a graph with a node missing does not recognise anything, so it
    should not look alive, like ``ros2 launch`` with ``on_exit=Shutdown()``)
    the others are then stopped, else they keep running.  Ctrl-C and SIGTERM
    only raise a flag the supervising loop polls (nothing is raised into
    the running code, and the handler takes no lock: :mod:`.signals`).  Returns the exit codes.
    """
    with stop_on_signals(second_raises=False) as stop:
        return _supervise(procs, stop, duration_s, stop_when_one_exits)


def _supervise(procs: GraphProcesses, stop: SignalStop, duration_s: float | None,
               stop_when_one_exits: bool) -> dict[str, int | None]:
    """The loop of :func:`run_until_interrupted`, inside its signal handlers."""
    deadline = None if duration_s is None else time.monotonic() + float(duration_s)
    reported: set[str] = set()
    try:
        procs.start()
        while not stop.is_set():
            remaining = None if deadline is None else deadline - time.monotonic()
            if remaining is not None and remaining <= 0:
                break
            done = procs.wait(timeout_s=0.5 if remaining is None else min(0.5, remaining), stop=stop)
            for n in done:
                if n.spec.name not in reported:
                    reported.add(n.spec.name)
                    procs.died.append(n.spec.name)
                    then = "; stopping the others" if stop_when_one_exits and len(reported) < len(procs.nodes) else ""
                    print(f"tactile launch: node {n.spec.name} exited with code {n.returncode}{then}",
                          file=sys.stderr, flush=True)
            if len(reported) == len(procs.nodes) or (reported and stop_when_one_exits):
                break
    finally:
        codes = procs.stop()
    return codes
