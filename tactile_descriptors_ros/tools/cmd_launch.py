"""``tactile launch ROBOT [--sim SCENE]``: start the robot's node graph without ``ros2 launch``.

The same nodes as ``launch/<robot>.launch.py`` (both come from
:func:`~tactile_descriptors_ros.launching.graph.build_graph`), started as
subprocesses of this interpreter with ``--ros-args --params-file <tmp yaml>
-r from:=to``; their output is forwarded with a ``[node]`` prefix; Ctrl-C
stops them cleanly (SIGINT to each, then SIGTERM/SIGKILL by PID).  When a
node ends on its own the others are stopped too and the exit code is 1.
``--set NODE.PARAM=VALUE``, ``--params-file`` and the robot's ``nodes:``
section are checked against the parameters each node declares (name, type
and accepted values) before anything starts, also with ``--print``.
``--no-drivers`` starts every node but the drivers, for a bag
replayed into them (``tactile replay``).
"""

from __future__ import annotations

import argparse
import json
import sys

import yaml

from ..errors import ConfigError
from ..launching.graph import LOG_LEVELS, build_graph, parameters_document
from ..launching.processes import GraphProcesses, localhost_environment, node_command, run_until_interrupted
from .arguments import positive_float

__all__ = ["register", "parse_set", "specs_from_args"]


def parse_set(items: list[str] | None) -> dict[str, dict]:
    """``["classifier_node.eta=0.5"]`` -> ``{"classifier_node": {"eta": 0.5}}`` (values read as YAML)."""
    out: dict[str, dict] = {}
    for item in items or []:
        target, sep, value = item.partition("=")
        node, dot, param = target.partition(".")
        if not sep or not dot or not node or not param:
            raise ConfigError(f"--set expects NODE.PARAMETER=VALUE, got {item!r}", key="--set")
        out.setdefault(node, {})[param] = yaml.safe_load(value)
    return out


def specs_from_args(args: argparse.Namespace):
    """The NodeSpecs selected by the command-line options."""
    return build_graph(args.robot, sim_scene=args.sim, sim_speed=args.sim_speed,
                       split_window_nodes=args.split_window_nodes,
                       model_path=args.model_path, use_sim_time=args.use_sim_time,
                       overrides=parse_set(args.set), namespace=args.namespace, drivers=args.drivers,
                       params_file=args.params_file, log_level=args.log_level or "")


def _run(args: argparse.Namespace) -> int:
    specs = specs_from_args(args)
    if args.print:
        if args.json:
            print(json.dumps({"nodes": [{"name": s.name, "executable": s.executable, "namespace": s.namespace,
                                         "parameters": s.parameters, "remappings": [list(r) for r in s.remappings],
                                         "command": node_command(s, "<params.yaml>")} for s in specs]}))
        else:
            print(yaml.safe_dump(parameters_document(specs), sort_keys=False), end="")
            for s in specs:
                print(" ".join(node_command(s, "<params.yaml>")))
        return 0
    # the nodes' lines go to stdout, or to stderr when stdout carries the JSON result
    procs = GraphProcesses(specs, env=localhost_environment(), output=sys.stderr if args.json else sys.stdout)
    print(f"tactile launch: starting {len(specs)} nodes ({', '.join(s.name for s in specs)}); Ctrl-C stops them",
          file=sys.stderr, flush=True)
    codes = run_until_interrupted(procs, duration_s=args.duration_s, stop_when_one_exits=True)
    failed = {k: v for k, v in codes.items() if v not in (0, None, -2, 130)}
    if args.json:
        print(json.dumps({"exit_codes": codes, "died": procs.died}))
    if procs.died:
        print(f"tactile launch: stopped the graph because {', '.join(procs.died)} ended", file=sys.stderr,
              flush=True)
    return 1 if failed or procs.died else 0


def register(subparsers) -> None:
    p = subparsers.add_parser("launch", help="start a robot's node graph (like ros2 launch)",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("robot", help="shipped robot (shadow_hand, nao) or a robot YAML path")
    p.add_argument("--sim", metavar="SCENE", default=None,
                   help="run the drivers on simulated sensors playing this scene (name or path)")
    p.add_argument("--sim-speed", type=positive_float, default=None, metavar="X",
                   help="with --sim: simulated seconds per wall second (default: the robot's sim_parameters, else "
                   "1.0; a machine too busy for real time needs less)")
    p.add_argument("--split-window-nodes", action="store_true",
                   help="one window node per body part (scale-out; pooled descriptors)")
    p.add_argument("--no-drivers", dest="drivers", action="store_false",
                   help="start every node but the drivers (replay a bag into them: tactile replay)")
    p.add_argument("--model-path", default=None, help="classifier model file")
    p.add_argument("--params-file", default=None, metavar="YAML",
                   help="a ROS 2 parameters file merged over the graph's parameters (checked like them)")
    p.add_argument("--log-level", choices=LOG_LEVELS, default=None, help="log level of every node")
    p.add_argument("--use-sim-time", action="store_true", help="set use_sim_time on every node (bag replay)")
    p.add_argument("--namespace", default="", help="namespace of the nodes")
    p.add_argument("--set", action="append", metavar="NODE.PARAM=VALUE", help="override a parameter (repeatable)")
    p.add_argument("--duration-s", type=float, default=None, help="stop after this many seconds")
    p.add_argument("--print", action="store_true", help="print the parameters and commands; start nothing")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=_run)
