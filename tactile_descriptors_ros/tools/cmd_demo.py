"""``tactile demo shadow_hand|nao``: a simulated robot through the live graph, learning online.

Starts the robot's node graph (the same as ``tactile launch ROBOT --sim
SCENE``: real drivers on the simulated transport speaking the wire format,
the window node, the classifier node with a fresh model in a temporary
folder) and plays the scene (``config/scenes/demo_<robot>.yaml`` by default).
This process listens to the prediction topic and, after each exploration's
prediction, publishes the true label of that exploration on the label topic
(the experimenter's part), so the classifier learns online: predict first,
then update (paper section VI-A).

The true label of a prediction is the scene exploration its window overlaps
most, by the sensor time stamps (the drivers stamp with the simulator's
clock in the demo).  Prints the online learning curve and ends with one
summary line of JSON.  ``accuracy`` is the online accuracy: predictions
made before their label was published, leaving out the first exploration of
each class (no online learner can name a class it has not been told of yet);
``accuracy_all`` counts those too.  ``chance`` is what guessing among the
classes taught before each scored prediction would score (:func:`chance_level`).
``learning_curve`` is the accuracy of
successive blocks of ``--block`` such predictions.

The window nodes compute the robot description's descriptor (the shipped
default, ``descriptor:`` in ``config/<robot>.yaml``); ``--channels`` picks
another channel mode for a comparison.  The summary's ``scored`` counts the
predictions behind ``accuracy`` (20 in the NAO demo scene).  Without
``--timeout-s`` the demo runs for the scene's length and then as long as
predictions keep coming (up to 30 s after the last one).

NAO's skin over CAN is about 175 000 frames per simulated second; the
simulated bus hands them to the driver in batches, which decodes them with
array operations faster than real time (``lab/docs/performance.md, section Wire``).  On a
busy machine ``--speed 0.5`` plays the scene at half of real time (the
drivers stamp with the simulator's clock, so windows and descriptors are
the same); ``--wire serial`` uses the skin serial framing.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import sys
import tempfile
import time
from pathlib import Path

from .arguments import positive_float, positive_int

__all__ = ["register", "run_demo", "match_exploration", "learning_curve", "never_windowed", "chance_level"]


def match_exploration(start_ns: int, end_ns: int, timings) -> int | None:
    """Index of the exploration whose contact interval overlaps ``[start_ns, end_ns)`` most (None if none)."""
    best, best_overlap = None, 0
    for i, t in enumerate(timings):
        overlap = min(end_ns, t.release_ns) - max(start_ns, t.onset_ns)
        if overlap > best_overlap:
            best, best_overlap = i, overlap
    return best


def never_windowed(windows: list[tuple[int, int]], timings) -> list[int]:
    """Indices of the scene explorations that no descriptor window overlaps (touches the graph missed)."""
    hit = {match_exploration(start, end, timings) for start, end in windows}
    return [i for i in range(len(timings)) if i not in hit]


def learning_curve(rows: list[dict], block: int) -> list[float]:
    """Accuracy of successive blocks of ``block`` scored predictions (the last block may be shorter)."""
    scored = [r["correct"] for r in rows if r.get("truth") and not r.get("first_of_class")]
    return [round(sum(scored[i:i + block]) / len(scored[i:i + block]), 3) for i in range(0, len(scored), block)]


def chance_level(rows: list[dict]) -> float | None:
    """Expected accuracy of guessing, over the scored predictions (those ``accuracy`` counts).

    A scored prediction is made when ``classes_known`` classes have been taught (labels published before
    it); a guess among them is right with probability ``1 / classes_known``.  The chance level is the
    mean of that over the scored predictions.  Classes taught but never scored (the NAO demo's large
    objects, one touch each, come after the materials) do not lower it, and early predictions, made
    among fewer classes, raise it above ``1 / n_classes``.
    """
    scored = [r for r in rows if r.get("truth") and not r.get("first_of_class")]
    if not scored:
        return None
    return sum(1.0 / r["classes_known"] for r in scored) / len(scored)


def run_demo(robot: str, scene: str | None = None, speed: float = 1.0, split_window_nodes: bool = False,
             timeout_s: float | None = None, verbose: bool = False, out=sys.stdout, channels: str = "robot",
             wire: str | None = None, block: int = 5) -> dict:
    """Run the demo; return the summary (see the module docstring).

    ``speed`` must be above 0.  ``channels``: descriptor channel mode of the window nodes (``robot``, the
    default: the robot description's; or ``averaged``, ``per_channel``).  ``wire``:
    framing of simulated skin buses (``can`` or ``serial``; default the
    driver's).
    """
    from ..errors import ConfigError

    if not (speed > 0 and speed != float("inf")):
        raise ConfigError(f"must be a finite number above 0, got {speed!r}", key="speed")
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    os.environ.setdefault("ROS_DOMAIN_ID", str(random.randint(1, 100)))
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from tactile_descriptors_msgs.msg import Descriptor, Label, Prediction

    from ..core.robot import load_robot
    from ..launching.graph import build_graph
    from ..launching.processes import GraphProcesses, localhost_environment
    from ..sim import load_scene, simulate

    t_start = time.monotonic()
    rob = load_robot(robot)
    scene_name = scene or f"demo_{rob.name}"
    sc = load_scene(scene_name)
    truth = simulate(sc).explorations  # ground truth: onset/release times and labels
    overrides: dict[str, dict] = {}
    for name, e in rob.nodes.items():
        if e.get("executable") in ("biotac_driver", "skin_driver"):
            overrides[name] = {"stamp_source": "device", "sim.speed": float(speed)}
            if wire is not None and e.get("executable") == "skin_driver":
                overrides[name]["sim.wire"] = wire
    if channels != "robot":
        windows_nodes = [s.name for s in build_graph(rob, sim_scene=scene_name, split_window_nodes=split_window_nodes)
                         if s.executable == "window_node"]
        overrides.update({w: {"descriptor.channels": channels} for w in windows_nodes})
    tmp = tempfile.TemporaryDirectory(prefix="tactile_demo_")
    specs = build_graph(rob, sim_scene=scene_name, split_window_nodes=split_window_nodes,
                        model_path=str(Path(tmp.name) / "model.json"), overrides=overrides)
    procs = GraphProcesses(specs, env=localhost_environment(), output=sys.stderr if verbose else None)
    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node("tactile_demo", context=context)
    qos = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
    label_pub = node.create_publisher(Label, "tactile/label", qos)
    rows: list[dict] = []
    seen_classes: set[str] = set()
    done_ids: set[int] = set()

    def on_prediction(msg) -> None:
        if msg.exploration_id in done_ids:
            return
        end = msg.window_end.sec * 1_000_000_000 + msg.window_end.nanosec
        eid = int(msg.exploration_id)
        idx = match_exploration(windows.get(eid, end - 1), end, truth)
        done_ids.add(eid)
        if idx is None:
            rows.append({"exploration_id": eid, "truth": None, "predicted": msg.class_name, "correct": False})
            print(f"exploration {eid:3d}: no scene exploration matches its window; not labelled", file=out,
                  flush=True)
            return
        label = truth[idx].exploration.label
        first = label not in seen_classes
        correct = bool(msg.has_model and msg.class_name == label)
        rows.append({"exploration_id": eid, "scene_index": idx, "truth": label, "predicted": msg.class_name,
                     "correct": correct, "first_of_class": first, "classes_known": len(seen_classes)})
        seen_classes.add(label)
        label_pub.publish(Label(exploration_id=eid, class_name=label))
        n_ok = sum(r["correct"] for r in rows)
        print(f"exploration {eid:3d}: true {label:<14s} predicted {msg.class_name or '(no model)':<14s} "
              f"{'ok ' if correct else 'bad'}  online accuracy {n_ok}/{len(rows)} = {n_ok / len(rows):.2f}",
              file=out, flush=True)

    windows: dict[int, int] = {}  # exploration id -> window start [ns], from the descriptors
    spans: list[tuple[int, int]] = []  # every descriptor's window [start, end) [ns]

    def on_descriptor(m) -> None:
        start = m.window_start.sec * 1_000_000_000 + m.window_start.nanosec
        windows[int(m.exploration_id)] = start
        spans.append((start, m.window_end.sec * 1_000_000_000 + m.window_end.nanosec))

    node.create_subscription(Descriptor, "tactile/descriptor", on_descriptor, qos)
    node.create_subscription(Prediction, "tactile/prediction", on_prediction, qos)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    # Without --timeout-s: the scene's length, then as long as predictions keep coming (a loaded machine
    # runs the graph behind the simulator's clock), giving up 30 s after the last one.
    scene_end = time.monotonic() + sc.duration_s / speed
    deadline = time.monotonic() + timeout_s if timeout_s is not None else None
    failed: list[str] = []
    try:
        procs.start()
        last_row, n_seen = time.monotonic(), 0
        while len(rows) < len(truth):
            now = time.monotonic()
            if len(rows) != n_seen:
                last_row, n_seen = now, len(rows)
            if deadline is not None and now >= deadline:
                break
            if deadline is None and now >= max(scene_end, last_row) + 30.0:
                break
            executor.spin_once(timeout_sec=0.1)
            for n in procs.exited():
                if n.spec.name not in failed:
                    failed.append(n.spec.name)
                    print(f"node {n.spec.name} exited with code {n.returncode}:\n  " + "\n  ".join(n.lines[-15:]),
                          file=sys.stderr, flush=True)
            if failed and len(failed) == len(procs.nodes):
                break
    except KeyboardInterrupt:
        pass
    finally:
        procs.stop()
        # the executor before the context: left to the garbage collector after the context's shutdown,
        # its SIGINT guard condition raises InvalidHandle at exit
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
        tmp.cleanup()
    n = len(rows)
    later = [r for r in rows if r.get("truth") and not r.get("first_of_class")]
    curve = learning_curve(rows, block)
    print(f"learning curve (accuracy of blocks of {block} predictions after the first of each class): "
          + " ".join(f"{a:.2f}" for a in curve), file=out, flush=True)
    chance = chance_level(rows)
    if later:
        print(f"online accuracy {sum(r['correct'] for r in later)}/{len(later)} = "
              f"{sum(r['correct'] for r in later) / len(later):.2f} over the scored explorations (chance "
              f"{chance:.2f}: a guess among the classes taught before each; "
              f"{len({r['truth'] for r in later})} classes scored, {len(seen_classes)} taught)", file=out, flush=True)
    missed = never_windowed(spans, truth)
    if missed:
        print(f"{len(missed)} of {len(truth)} scene touches were never windowed (no descriptor overlaps them): "
              f"scene explorations {', '.join(map(str, missed))}", file=out, flush=True)
    return {
        "robot": rob.name, "scene": sc.name, "explorations": len(truth), "predictions": n,
        "accuracy": round(sum(r["correct"] for r in later) / len(later), 4) if later else None,
        "scored": len(later), "accuracy_all": round(sum(r["correct"] for r in rows) / n, 4) if n else None,
        "chance": None if chance is None else round(chance, 4), "learning_curve": curve,
        "classes": len(seen_classes), "unmatched": sum(1 for r in rows if r.get("truth") is None),
        "windowed": len(truth) - len(missed), "never_windowed": missed,
        "channels": channels, "speed": speed, "failed_nodes": failed,
        "wall_time_s": round(time.monotonic() - t_start, 1),
    }


def _run(args: argparse.Namespace) -> int:
    summary = run_demo(args.robot, args.scene, args.speed, args.split_window_nodes, args.timeout_s, args.verbose,
                       channels=args.channels, wire=args.wire, block=args.block)
    print(json.dumps(summary), flush=True)
    return 0 if summary["predictions"] and not summary["failed_nodes"] else 1


def register(subparsers) -> None:
    p = subparsers.add_parser("demo", help="simulated robot through the live graph, learning online",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("robot", help="shadow_hand or nao (or a robot YAML path with a nodes: section)")
    p.add_argument("--scene", default=None, help="scene name or path (default demo_<robot>)")
    p.add_argument("--speed", type=positive_float, default=1.0, help="simulated seconds per wall second (> 0)")
    p.add_argument("--channels", default="robot", choices=("robot", "per_channel", "averaged"),
                   help="descriptor channel mode of the window nodes (default robot: the robot description's)")
    p.add_argument("--wire", default=None, choices=("can", "serial"), help="framing of simulated skin buses")
    p.add_argument("--block", type=positive_int, default=5, help="predictions per learning-curve point")
    p.add_argument("--split-window-nodes", action="store_true", help="one window node per body part")
    p.add_argument("--timeout-s", type=float, default=None, help="give up after this long")
    p.add_argument("--verbose", action="store_true", help="forward the nodes' output to stderr")
    p.add_argument("--json", action="store_true", help="(the summary line is always JSON)")
    p.set_defaults(func=_run)
