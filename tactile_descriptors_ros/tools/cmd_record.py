"""``tactile record [TOPICS | --regex PATTERN | --all] -o BAG``: record live topics into a bag.

Raw subscriptions: the CDR bytes are written exactly as received, with each
topic's type, type hash, full message definition and the QoS its publishers
offered (so ``tactile replay`` and ``ros2 bag play`` offer the same).  A topic
is subscribed once it has a publisher.  Stops on Ctrl-C or after
``--duration``; the bag is always closed cleanly.  See docs/bags.md.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

__all__ = ["register", "run"]


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("record", help="record live topics into a bag",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("topics", nargs="*", help="topics to record")
    p.add_argument("--regex", "-e", action="append", default=None, metavar="PATTERN",
                   help="also record topics matching this pattern (re.search; repeatable: any of them)")
    p.add_argument("--all", "-a", dest="all_topics", action="store_true",
                   help="record every topic (except /rosout and /parameter_events unless named)")
    p.add_argument("--exclude", "-x", default=None, help="never record topics matching this pattern")
    p.add_argument("-o", "--output", type=Path, default=None,
                   help="bag directory to create (default rosbag2_YYYY_MM_DD-HH_MM_SS)")
    p.add_argument("--storage", "-s", choices=("mcap", "sqlite3"), default="mcap", help="bag storage (default mcap)")
    p.add_argument("--duration", "-d", type=float, default=None, help="stop after this many seconds")
    p.add_argument("--max-messages", type=int, default=None, help="stop after this many messages")
    p.add_argument("--use-sim-time", action="store_true", help="log times from /clock")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout at the end")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import rclpy
    from rclpy.executors import ExternalShutdownException

    from ..bags.live import TopicSelector
    from ..bags.record import record
    from ..launching.signals import stop_on_signals

    selector = TopicSelector(args.topics, regex=args.regex, all_topics=args.all_topics, exclude=args.exclude)
    output = args.output or Path(time.strftime("rosbag2_%Y_%m_%d-%H_%M_%S"))
    context = rclpy.Context()
    rclpy.init(context=context)
    report = None
    interrupted = False
    try:
        with stop_on_signals() as stop:
            if not args.json:
                print(f"recording to {output} ({args.storage}); Ctrl-C to stop", file=sys.stderr, flush=True)
            report = record(str(output), selector, storage=args.storage, duration_s=args.duration,
                            context=context, stop=stop, use_sim_time=args.use_sim_time,
                            max_messages=args.max_messages)
            interrupted = stop.is_set()
    except (KeyboardInterrupt, ExternalShutdownException):
        interrupted = True
    finally:
        if context.ok():
            rclpy.shutdown(context=context)
    from ..bags.io import bag_info

    info = bag_info(output)
    if args.json:
        out = info.to_dict()
        out["interrupted"] = interrupted
        if report is not None:
            out["refused"] = report.refused
        print(json.dumps(out))
        return 0
    print(f"wrote {output}: {info.message_count} messages, {info.duration_ns / 1e9:.3f} s")
    for name, t in info.topics.items():
        print(f"  {name:<32} {t.msgtype:<48} {t.message_count:>7}")
    if report is not None:
        for name, why in report.refused.items():
            print(f"  not recorded {name}: {why}")
    return 0
