"""``tactile echo TOPIC``: ``ros2 topic echo`` made readable for tactile messages.

Per message: per-channel min/max/mean and INVALID_COUNT samples, force in
newtons, message rate, lost frames (sequence gaps) and time-stamp gaps;
for a Descriptor the contact and quality flags per body part (the QUALITY_*
bit mask by name); for a Prediction the top scores.  ``--raw`` prints the
full message as YAML.  ``--bag BAG`` reads the topic from a bag instead of
the live graph.  See docs/bags.md.
"""

from __future__ import annotations

import argparse
import json
import sys

__all__ = ["register", "run"]


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("echo", help="print tactile messages of a topic, summarised",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("topic", help="topic name, e.g. /tactile/biotac")
    p.add_argument("--bag", default=None, help="read the topic from this bag instead of the live graph")
    p.add_argument("--raw", action="store_true", help="print the full message as YAML")
    p.add_argument("--count", "-n", type=int, default=None, help="stop after N messages")
    p.add_argument("--timeout", type=float, default=None, help="live: stop after this many seconds")
    p.add_argument("--type", dest="msgtype", default=None, help="live: message type (default: from the graph)")
    p.add_argument("--top-k", type=int, default=3, help="scores shown for a Prediction (default 3)")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout at the end")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..bags.echo import echo_bag, echo_live, type_constants
    from ..bags.summary import EchoTracker, format_summary, message_to_dict, to_yaml
    from ..bags.types import tactile_typestore

    if args.count is not None and args.count < 1:
        print("tactile echo: error: --count must be at least 1", file=sys.stderr)
        return 2
    tracker = EchoTracker(type_constants(tactile_typestore()), top_k=args.top_k)
    collected = []
    msgtype = None
    rclpy_context = None
    try:
        if args.bag:
            source = echo_bag(args.bag, args.topic, args.count)
        else:
            import rclpy

            rclpy_context = rclpy.Context()
            rclpy.init(context=rclpy_context)
            source = echo_live(args.topic, args.count, args.timeout, msgtype=args.msgtype, context=rclpy_context)
        for msg, decoded in source:
            summary = tracker.summarize(msg.topic, msg.msgtype, decoded, msg.log_time_ns)
            if msg.topic.lstrip("/") != args.topic.lstrip("/"):
                continue  # a descriptor topic's layout: learned by the tracker, not shown
            msgtype = msg.msgtype
            if args.json:
                if args.raw:
                    collected.append({"log_time_ns": msg.log_time_ns, "message": message_to_dict(decoded)})
                else:
                    collected.append(summary)
            elif args.raw:
                print(to_yaml(decoded) + "---", flush=True)
            else:
                print(format_summary(summary), flush=True)
    except KeyboardInterrupt:
        pass
    finally:
        if rclpy_context is not None and rclpy_context.ok():
            import rclpy

            rclpy.shutdown(context=rclpy_context)
    if args.json:
        print(json.dumps({"topic": args.topic, "type": msgtype, "source": args.bag or "live",
                          "count": len(collected), "messages": collected, "streams": tracker.stream_health()}))
    return 0
