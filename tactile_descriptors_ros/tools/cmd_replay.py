"""``tactile replay BAG``: play a bag onto live topics with its original timing.

Publishes the bag's CDR bytes as recorded, with each topic's QoS adapted
from the bag's offered_qos_profiles (reliability, durability, depth).  With
``--clock`` it publishes /clock (rosgraph_msgs/Clock) at the bag's time, so
nodes started with use_sim_time run on the recorded time line.  ``--info``
prints what is in the bag (like ``ros2 bag info``) and exits.
See docs/bags.md.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

__all__ = ["register", "run", "clock_option", "DEFAULT_CLOCK_HZ"]

#: /clock ticks per second of bag time with a bare ``--clock``.
DEFAULT_CLOCK_HZ = 100.0


def clock_option(bag: Path | None, clock: str | None) -> tuple[Path, float | None]:
    """The bag and the /clock rate from the parsed ``BAG`` and ``--clock [HZ]``.

    ``--clock`` takes an optional value, so in ``tactile replay --clock BAG``
    argparse hands BAG to ``--clock``: a value that is not a number is the
    bag when no other bag was given.

    Raises
    ------
    ConfigError
        No bag, or a ``--clock`` value that is neither a rate nor the bag.
    """
    from ..errors import ConfigError

    rate = None
    if clock is not None:
        try:
            rate = float(clock)
        except ValueError:
            if bag is not None:
                raise ConfigError(f"--clock takes a rate in Hz, got {clock!r}", key="--clock") from None
            bag, rate = Path(clock), DEFAULT_CLOCK_HZ
        else:
            if not rate >= 0:  # 0: /clock only at the messages
                raise ConfigError(f"--clock rate must not be negative, got {clock!r}", key="--clock")
    if bag is None:
        raise ConfigError("no bag given: tactile replay BAG", key="BAG")
    return bag, rate


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("replay", help="play a bag onto live topics",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("bag", type=Path, nargs="?", help="bag directory (or a .mcap / .db3 file)")
    p.add_argument("--rate", "-r", type=float, default=1.0, help="speed factor (default 1)")
    p.add_argument("--start-offset", type=float, default=0.0, help="skip this many seconds of the bag")
    p.add_argument("--loop", "-l", action="store_true", help="play again from the start at the end")
    p.add_argument("--topics", nargs="+", default=None, help="only these topics")
    # ``--clock [HZ]`` as in ``ros2 bag play``; argparse gives an optional value
    # whatever follows, so ``--clock BAG`` is told apart after parsing (clock_option).
    p.add_argument("--clock", nargs="?", const=str(DEFAULT_CLOCK_HZ), default=None, metavar="HZ",
                   help=f"publish /clock; ticks at HZ of bag time between messages (default {DEFAULT_CLOCK_HZ:g})")
    p.add_argument("--remap", nargs="+", default=[], metavar="FROM:=TO", help="publish bag topic FROM on TO")
    p.add_argument("--wait-for-subscribers", type=float, default=0.0, metavar="S",
                   help="wait up to S seconds for a subscriber on every topic before playing")
    p.add_argument("--delay", type=float, default=0.0, metavar="S", help="wait S seconds before playing")
    p.add_argument("--info", action="store_true", help="print the bag's contents and exit")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout at the end")
    p.set_defaults(func=run)


def _parse_remaps(items: list[str]) -> dict[str, str]:
    from ..errors import BagError

    out = {}
    for item in items:
        src, sep, dst = item.partition(":=")
        if not sep or not src or not dst:
            raise BagError(f"bad remap {item!r}: use FROM:=TO")
        out[src] = dst
    return out


def _print_info(bag: Path, as_json: bool) -> None:
    from ..bags.io import bag_info
    from ..bags.qos import qos_to_dict

    info = bag_info(bag)
    if as_json:
        print(json.dumps(info.to_dict()))
        return
    print(f"bag:       {info.path} ({info.storage}, rosbag2 metadata v{info.version})")
    print(f"duration:  {info.duration_ns / 1e9:.3f} s, start {info.start_ns / 1e9:.6f}")
    print(f"messages:  {info.message_count}")
    for name, t in info.topics.items():
        qos = ", ".join(f"{q['reliability']}/{q['durability']}/depth {q['depth']}"
                        for q in map(qos_to_dict, t.offered_qos)) or "no QoS recorded"
        print(f"  {name:<28} {t.msgtype:<46} {t.message_count:>7}  [{qos}]")
        print(f"  {'':<28} {t.type_hash}")


def run(args: argparse.Namespace) -> int:
    args.bag, args.clock = clock_option(args.bag, args.clock)
    if args.info:
        _print_info(args.bag, args.json)
        return 0
    import rclpy

    from ..bags.replay import PlayOptions, play
    from ..launching.signals import stop_on_signals

    options = PlayOptions(
        rate=args.rate, start_offset_s=args.start_offset, loop=args.loop,
        topics=tuple(args.topics) if args.topics else None, clock=args.clock is not None,
        clock_rate_hz=args.clock if args.clock is not None else 0.0,
        wait_for_subscribers_s=args.wait_for_subscribers, delay_s=args.delay, remap=_parse_remaps(args.remap),
    )
    options.validate()
    context = rclpy.Context()
    rclpy.init(context=context)
    report = None
    try:
        with stop_on_signals() as stop:
            report = play(str(args.bag), options, context=context, stop=stop)
    except KeyboardInterrupt:
        pass
    finally:
        if context.ok():
            rclpy.shutdown(context=context)
    if report is None:
        print("replay interrupted", file=sys.stderr)
        return 0
    if args.json:
        print(json.dumps(report.to_dict()))
        return 0
    print(f"published {report.message_count} messages in {report.wall_s:.2f} s ({report.loops} pass(es)), "
          f"{report.clock_messages} /clock, max lag {1000 * report.max_lag_s:.1f} ms")
    for name, n in report.published.items():
        q = report.qos[name]
        print(f"  {name:<32} {n:>7}  [{q['reliability']}/{q['durability']}/depth {q['depth']}]")
    for name, why in report.skipped.items():
        print(f"  skipped {name}: {why}")
    return 0
