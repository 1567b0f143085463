"""``tactile bench``: time the descriptor path against a naive per-signal baseline.

In one run, after checking that the package's descriptor equals the naive
baseline's on the same window (it aborts otherwise), times on one core
(BLAS/OpenMP pools limited to one thread): a Shadow Hand window (5 BioTacs,
2 s), a NAO window (116 skin cells, 2 s), 1,000 and 10,000 skin cells (the
baseline extrapolated from a measured subset), the scaling with window length
(0.5 to 10 s), and the windowing cost per NAO message (Windower.add vs
add_many).  The compiled kernel is loaded (or compiled) before timing and
checked against the reference (core/descriptors.py); then the shipped feature groups (the best measured mode) on a
Shadow Hand and a NAO window, checked against the evaluation's values per
cell and group before timing; the report ends with the targets, met or not
(``targets`` in ``--json``).
``--latency`` also measures sensor stamp -> Prediction through the ROS node
graph; ``--scale-graph --cells N`` instead runs N skin cells through skin
drivers and one window node per body part, each its own process
(lab/docs/performance.md, section Scale); ``--view-overhead`` instead measures the views' CPU
on the NAO graph at full rate against the same graph without them
(docs/view.md); ``--executor-overhead`` instead measures the CPU per message
taken in each executor a node can spin in (``TACTILE_EXECUTOR``).  Reading
the numbers: lab/docs/performance.md.
"""

from __future__ import annotations

import argparse
import json
import signal
import sys

from tactile_descriptors_ros.tools.arguments import number_list

__all__ = ["register", "run"]


def _layouts(text: str) -> list[str]:
    """argparse type of ``--executor-layouts``: names among the executor bench's layouts, joined by ','."""
    from tactile_descriptors_lab.bench.executor_overhead import LAYOUTS

    names = [x.strip() for x in text.split(",") if x.strip()]
    if not names or any(x not in LAYOUTS for x in names):
        raise argparse.ArgumentTypeError(f"expected layouts among {', '.join(LAYOUTS)} joined by ',', got {text!r}")
    return list(dict.fromkeys(names))


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("bench", help="time the descriptor path against a naive baseline",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--repeat", type=int, default=7, help="timed repeats per case (median reported; default 7)")
    p.add_argument("--sizes", type=number_list("cell counts", integer=True, empty=True), default=[1000, 10000],
                   help="large skins to time, comma-separated cell counts (default 1000,10000)")
    p.add_argument("--lengths", type=number_list("window lengths in seconds", high=60, empty=True),
                   default=[0.5, 1.0, 2.0, 5.0, 10.0],
                   help="NAO window lengths for the scaling table, seconds (default 0.5,1,2,5,10)")
    p.add_argument("--baseline-cells", type=int, default=116,
                   help="cells on which the baseline of a large skin is measured (default 116)")
    p.add_argument("--no-windowing", action="store_true", help="skip the windowing measurement")
    p.add_argument("--reference-only", action="store_true",
                   help="time the reference backend only, no compiled code (as without numba, or TACTILE_NO_NUMBA=1)")
    p.add_argument("--latency", action="store_true",
                   help="also measure sensor stamp -> Prediction latency through window_node + classifier_node")
    p.add_argument("--latency-s", type=float, default=8.0, help="seconds of NAO data for --latency (default 8)")
    p.add_argument("--latency-batch-s", type=float, default=None,
                   help="sample time per SkinPartFrames for --latency (default: the skin driver's batch_s in "
                        "config/nao.yaml)")
    p.add_argument("--latency-lateness-s", type=float, default=None,
                   help="window_node window.lateness_s for --latency (default: config/nao.yaml's)")
    p.add_argument("--latency-groups", default=None,
                   help="window_node descriptor.groups for --latency, joined by + (default: the robot's shipped "
                        "groups; 'paper' times the graph with the paper's descriptor)")
    p.add_argument("--latency-mode", choices=("fixed", "exploration", "both"), default="both",
                   help="window mode of --latency: fixed windows (timed from their end), explorations (timed from "
                        "the release decision) or both runs (default)")
    p.add_argument("--latency-split-window-nodes", action="store_true",
                   help="one window node per body part, each its own process (the launcher's scale-out option)")
    p.add_argument("--latency-drain-max", type=int, default=None,
                   help="window_node frames.drain_max for --latency (default: the robot's; 0 = one message "
                   "per callback)")
    p.add_argument("--latency-no-micro", action="store_true",
                   help="skip the per-message cost micro benchmark of --latency")
    p.add_argument("--latency-in-process", action="store_true",
                   help="run window_node and classifier_node in the bench process (default: own processes)")
    p.add_argument("--model-save", action="store_true",
                   help="only measure the classifier's durable save per label: journal vs whole-file rewrite")
    p.add_argument("--model-save-classes", type=int, default=1000,
                   help="classes in the model for --model-save (default 1000)")
    p.add_argument("--soak", type=float, default=None, metavar="SECONDS",
                   help="instead of timing: run the NAO graph at full rate for SECONDS and report per-node RSS "
                        "over time, CPU, lost and late frames (docs/hardcases.md)")
    p.add_argument("--soak-robot", default="nao", help="robot whose graph --soak runs (default nao)")
    p.add_argument("--soak-sample-s", type=float, default=5.0, help="sampling period of --soak [s] (default 5)")
    p.add_argument("--soak-set", action="append", metavar="NODE.PARAM=VALUE",
                   help="a parameter of one of --soak's nodes, on top of the robot's (repeatable)")
    p.add_argument("--scale-graph", action="store_true",
                   help="instead of timing: run a synthetic skin of --cells cells through skin drivers and one "
                        "window node per body part, each its own process, and report CPU per process, lost "
                        "frames, windows and whether it kept up in real time (lab/docs/performance.md, section Scale)")
    p.add_argument("--view-overhead", action="store_true",
                   help="instead of timing: feed the NAO's contact node at full rate (700 frames messages/s) "
                        "with the views (its markers and images, tactile view with one page) and without, "
                        "--rounds times each, and report the views' CPU against the 10 %% target (docs/view.md)")
    p.add_argument("--executor-overhead", action="store_true",
                   help="instead of timing: the CPU a node pays per message taken in each executor it can spin in "
                        "(TACTILE_EXECUTOR single and events), one NAO body part's frames at 700 messages/s, "
                        "--rounds alternating runs of --seconds each (lab/docs/performance.md, section Latency)")
    p.add_argument("--serialized", action="store_true",
                   help="with --executor-overhead: also take the frames as their bytes and read them in one "
                        "compiled pass, as the nodes do (frames.serialized)")
    p.add_argument("--executor-layouts", type=_layouts, default=["part"], metavar="L,L,...",
                   help="with --executor-overhead: what a message holds, among part (the NAO's largest body part, "
                        "700/s), parts (each body part in turn, 700/s) and robot (every cell in one message a "
                        "batch, 100/s); parts,robot compares the two per cell-second (default part)")
    p.add_argument("--read-cost", action="store_true",
                   help="instead of timing: the skin driver's read path in one process (decode, stamp, cut, write "
                        "the messages' bytes) on --read-cost-cells cells read every --read-period-s, CPU per read "
                        "compiled, with numpy's stamping, and numpy throughout, checked equal first, --rounds "
                        "alternating runs each (lab/docs/performance.md, section Scale)")
    p.add_argument("--read-cost-cells", type=int, default=200, help="skin cells of --read-cost (default 200)")
    p.add_argument("--read-cost-parts", type=int, default=1,
                   help="body parts the cells of --read-cost make, a message each per batch (default 1; the NAO: 7)")
    p.add_argument("--read-cost-stamps", choices=("device", "clock"), default="device",
                   help="the stamps of --read-cost: the simulator's bus times as the scale graph takes them "
                        "(device, default) or estimated on the host clock as a robot's driver does (clock, a driver's default)")
    p.add_argument("--rounds", type=int, default=2, help="runs with and without the views of --view-overhead, "
                   "runs of each executor of --executor-overhead, of each path of --read-cost (default 2 each)")
    p.add_argument("--cells", type=int, default=10000, help="skin cells of --scale-graph (default 10000)")
    p.add_argument("--parts", type=int, default=None,
                   help="body parts of --scale-graph, one driver and one window node each (default: one per 500 "
                        "cells)")
    p.add_argument("--seconds", type=float, default=30.0,
                   help="measurement time of --scale-graph and of each --view-overhead run after the warm-up [s] "
                        "(default 30)")
    p.add_argument("--settle-s", type=float, default=5.0,
                   help="time between the first descriptor of every body part (--view-overhead: the first "
                        "contact) and the measurement [s] (default 5)")
    p.add_argument("--warm-up-s", type=float, default=180.0,
                   help="longest wait for the first descriptor of every body part before --scale-graph measures "
                        "anyway [s] (default 180)")
    p.add_argument("--groups", default="paper",
                   help="descriptor feature groups of --scale-graph, comma-separated (default paper)")
    p.add_argument("--batch-s", type=float, default=None,
                   help="the skin drivers' batch_s for --scale-graph and --read-cost (default: the NAO graph's)")
    p.add_argument("--read-period-s", type=float, default=None,
                   help="the skin drivers' read_period_s for --scale-graph and --read-cost (default: the NAO graph's; "
                        "0 reads as soon as frames are due, not for --read-cost)")
    p.add_argument("--one-driver", action="store_true",
                   help="--scale-graph with one skin driver for all body parts instead of one per body part")
    p.add_argument("--hosts", type=int, default=0,
                   help="--scale-graph across hosts: this many body-part hosts and one classifier host, network "
                        "namespaces joined by veth links (needs root and ip); 0: one machine (default)")
    p.add_argument("--link-drop-s", type=float, default=None,
                   help="--scale-graph --hosts: take one body-part host's link down for this long during the "
                        "measurement, and report what it cost and how the graph recovered")
    p.add_argument("--link-drop-host", type=int, default=0,
                   help="the body-part host whose link --link-drop-s drops (default 0)")
    p.add_argument("--discovery", choices=("subnet", "server"), default="subnet",
                   help="--scale-graph --hosts: how participants find each other: DDS's simple discovery over the "
                        "hosts' links (subnet, default) or a Fast DDS discovery server on the classifier's host")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    if args.soak is not None:
        return _soak(args)
    if args.scale_graph:
        return _scale_graph(args)
    if args.view_overhead:
        return _view_overhead(args)
    if args.executor_overhead:
        return _executor_overhead(args)
    if args.read_cost:
        return _read_cost(args)

    from tactile_descriptors_lab.bench.bench import BenchMismatch, format_report, run_bench
    from tactile_descriptors_ros.core import fast

    if args.model_save:
        from tactile_descriptors_lab.bench.model_save import format_model_save, measure_model_save

        try:
            res = measure_model_save(classes=args.model_save_classes)
        except ValueError as exc:
            print(f"tactile bench: error: {exc}", file=sys.stderr)
            return 2
        print(json.dumps(res) if args.json else format_model_save(res))
        return 0
    if args.repeat < 1 or args.baseline_cells < 1:
        print("tactile bench: error: --repeat and --baseline-cells must be at least 1", file=sys.stderr)
        return 2
    steps = 3 + len(args.sizes) + len(args.lengths) + (0 if args.no_windowing else 1)
    bar = tqdm(total=steps, desc="bench", unit="case", file=sys.stderr, leave=False)

    def progress(msg: str) -> None:
        bar.set_postfix_str(msg)
        bar.update(1)

    if args.reference_only:
        fast.set_backend(fast.REFERENCE)
    try:
        report = run_bench(repeat=args.repeat, sizes=args.sizes, lengths_s=args.lengths,
                           baseline_cells=args.baseline_cells, windowing=not args.no_windowing,
                           progress=progress)
    except BenchMismatch as exc:
        bar.close()
        print(f"tactile bench: error: {exc}", file=sys.stderr)
        return 1
    bar.close()
    if args.latency:
        from tactile_descriptors_lab.bench.latency import measure_latency

        kwargs = dict(duration_s=args.latency_s, batch_s=args.latency_batch_s, lateness_s=args.latency_lateness_s,
                      in_process=args.latency_in_process, split_window_nodes=args.latency_split_window_nodes,
                      drain_max=args.latency_drain_max,
                      groups=args.latency_groups.split("+") if args.latency_groups else None)
        try:
            if args.latency_mode in ("fixed", "both"):
                report.latency = measure_latency(mode="fixed", micro=not args.latency_no_micro, **kwargs)
            if args.latency_mode in ("exploration", "both"):
                report.latency_exploration = measure_latency(mode="exploration", micro=False, **kwargs)
        except (ImportError, RuntimeError, ValueError) as exc:
            print(f"tactile bench: error: latency measurement failed: {exc}", file=sys.stderr)
            return 1
    if args.json:
        print(json.dumps(report.to_dict(), default=float))
    else:
        print(format_report(report))
    return 0


def _seconds_bar(total_s: float, desc: str):
    """A progress bar over ``total_s`` seconds on stderr and the ``progress(elapsed_s, text)`` that moves it."""
    from tqdm import tqdm

    bar = tqdm(total=round(total_s), desc=desc, unit="s", file=sys.stderr, leave=False)

    def progress(elapsed_s: float, text: str) -> None:
        bar.n = min(round(elapsed_s), bar.total)
        bar.set_postfix_str(text)
        bar.refresh()

    return bar, progress


def _soak(args: argparse.Namespace) -> int:
    from tactile_descriptors_lab.bench.soak import format_soak, run_soak
    from tactile_descriptors_ros.tools.cmd_launch import parse_set

    if not args.soak > 0 or not args.soak_sample_s > 0:
        print("tactile bench: error: --soak and --soak-sample-s must be positive", file=sys.stderr)
        return 2
    bar, progress = _seconds_bar(args.soak, "soak")
    try:
        report = run_soak(args.soak, robot=args.soak_robot, sample_s=args.soak_sample_s, progress=progress,
                          overrides=parse_set(args.soak_set))
    except (RuntimeError, ImportError) as exc:
        bar.close()
        print(f"tactile bench: error: soak failed: {exc}", file=sys.stderr)
        return 1
    bar.close()
    print(json.dumps(report.to_dict(), default=float) if args.json else format_soak(report))
    return 0


def _scale_graph(args: argparse.Namespace) -> int:
    from tactile_descriptors_lab.bench.scale_graph import format_scale_graph, run_scale_graph
    from tactile_descriptors_ros.errors import ConfigError

    if args.hosts:
        from tactile_descriptors_lab.bench.netns import namespaces_unavailable

        why = namespaces_unavailable()
        if why:
            print(f"tactile bench: error: --hosts needs network namespaces: {why}", file=sys.stderr)
            return 2
    if args.cells < 1 or (args.parts is not None and args.parts < 1) or not args.seconds > 0 \
            or not args.settle_s >= 0 or (args.batch_s is not None and not args.batch_s > 0) \
            or (args.read_period_s is not None and not args.read_period_s >= 0) or not args.warm_up_s > 0:
        print("tactile bench: error: --cells, --parts, --seconds, --batch-s and --warm-up-s must be positive, "
              "--settle-s and --read-period-s at least 0", file=sys.stderr)
        return 2
    groups = tuple(g.strip() for g in args.groups.split(",") if g.strip())
    bar, progress = _seconds_bar(args.seconds, "scale graph")

    def on_term(signum, frame):  # SIGTERM stops the graph like Ctrl-C: its processes and hosts are removed
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, on_term)
    try:
        report = run_scale_graph(args.cells, parts=args.parts, seconds=args.seconds, settle_s=args.settle_s,
                                 groups=groups, batch_s=args.batch_s, read_period_s=args.read_period_s,
                                 one_driver=args.one_driver, warm_up_timeout_s=args.warm_up_s,
                                 hosts=args.hosts, link_drop_s=args.link_drop_s, link_drop_host=args.link_drop_host,
                                 discovery=args.discovery,
                                 progress=progress)
    except (RuntimeError, ImportError, ConfigError) as exc:
        bar.close()
        print(f"tactile bench: error: scale graph failed: {exc}", file=sys.stderr)
        return 1
    bar.close()
    print(json.dumps(report.to_dict(), default=float) if args.json else format_scale_graph(report))
    return 0


def _view_overhead(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from tactile_descriptors_lab.bench.view_overhead import format_view_overhead, measure

    if args.rounds < 1 or not args.seconds > 0 or not args.settle_s >= 0:
        print("tactile bench: error: --rounds and --seconds must be positive, --settle-s at least 0", file=sys.stderr)
        return 2
    bar = tqdm(total=2 * args.rounds, desc="view overhead", unit="run", file=sys.stderr, leave=False)
    started = [0]

    def progress(text: str) -> None:
        if text.endswith("starting"):  # a run begins: the ones before it are done
            bar.n = started[0]
            started[0] += 1
        bar.set_postfix_str(text)  # refreshes the bar

    try:
        report = measure(args.seconds, args.settle_s, args.rounds, progress=progress)
    except (RuntimeError, ImportError) as exc:
        bar.close()
        print(f"tactile bench: error: view overhead failed: {exc}", file=sys.stderr)
        return 1
    bar.close()
    print(json.dumps(report, default=float) if args.json else format_view_overhead(report))
    return 0


def _read_cost(args: argparse.Namespace) -> int:
    from tactile_descriptors_lab.bench.read_cost import format_read_cost, read_cost

    if min(args.read_cost_cells, args.read_cost_parts, args.rounds) < 1 \
            or (args.batch_s is not None and not args.batch_s > 0):
        print("tactile bench: error: --read-cost-cells, --read-cost-parts, --rounds and --batch-s must be positive",
              file=sys.stderr)
        return 2
    print(f"tactile bench: the skin driver's read path, {args.read_cost_cells} cells in {args.read_cost_parts} body "
          f"part(s), {args.read_cost_stamps} stamps, {args.rounds} run(s) of each path ...", file=sys.stderr)
    try:
        report = read_cost(args.read_cost_cells, parts=args.read_cost_parts, read_period_s=args.read_period_s,
                           batch_s=args.batch_s, repeat=args.rounds, stamp_source=args.read_cost_stamps)
    except RuntimeError as exc:
        print(f"tactile bench: error: read cost: {exc}", file=sys.stderr)
        return 1
    print(json.dumps(report) if args.json else format_read_cost(report))
    return 0


def _executor_overhead(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from tactile_descriptors_lab.bench.executor_overhead import format_executor_overhead, measure

    if args.rounds < 1 or not args.seconds > 0:
        print("tactile bench: error: --rounds and --seconds must be positive", file=sys.stderr)
        return 2
    taken = ("message", "bytes") if args.serialized else ("message",)
    bar = tqdm(total=2 * len(taken) * len(args.executor_layouts) * args.rounds, desc="executor overhead",
               unit="run", file=sys.stderr, leave=False)

    def progress(text: str) -> None:
        bar.set_postfix_str(text)
        bar.update(1)

    try:
        report = measure(args.seconds, args.rounds, progress=progress, taken=taken, layouts=args.executor_layouts)
    except RuntimeError as exc:
        bar.close()
        print(f"tactile bench: error: executor overhead failed: {exc}", file=sys.stderr)
        return 1
    bar.close()
    print(json.dumps(report) if args.json else format_executor_overhead(report))
    return 0
