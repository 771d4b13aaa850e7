"""`veg-area record`, `play` and `bag-recover`: rosbag2 bags as `ros2 bag` makes and replays them (record and
play run a ROS 2 node in this process), and a readable bag rebuilt from a killed MCAP recording."""

from __future__ import annotations

import argparse
import sys

from .common import EXIT_USAGE, CliError, check_writable, positive_float


def add_parsers(sub: argparse._SubParsersAction) -> None:
    rec = sub.add_parser("record", help="record topics into a rosbag2 bag (MCAP, or sqlite3) as they come, "
                         "serialized (ROS 2 node; Ctrl-C closes the bag)")
    rec.add_argument("topics", nargs="*", default=None,
                     help="topics (default: image_raw camera_info projected_area projected_area/info); a topic "
                          "never seen, or seen but never received, is a warning and exit 1")
    rec.add_argument("--all", action="store_true", help="every topic on the graph")
    rec.add_argument("--duration", type=positive_float, default=None, metavar="S", help="stop after S seconds")
    rec.add_argument("-o", "--output", help="bag folder to create (default veg_area_<date-time>)")
    rec.add_argument("--storage", default="mcap", choices=["mcap", "sqlite3"])
    rec.set_defaults(func=cmd_record)

    play = sub.add_parser("play", help="replay a rosbag2 bag (or a ROS 1 .bag, as ROS 2 messages) at the recorded "
                          "pace with the recorded QoS, as 'ros2 bag play' does (ROS 2 node; stops at the end)")
    play.add_argument("bag", help="the bag folder (or .mcap/.db3 file, or ROS 1 .bag)")
    play.add_argument("--topics", nargs="+", default=None, help="topics to replay (default: all)")
    play.add_argument("--rate", type=positive_float, default=1.0, help="pace, 1 = as recorded")
    play.add_argument("--delay", type=float, default=1.0, metavar="S",
                      help="seconds to wait before the first message, for subscribers to connect (default 1)")
    play.add_argument("--wait-for-subscribers", type=float, default=5.0, metavar="S",
                      help="then wait up to S seconds until every replayed topic has a subscriber (default 5)")
    play.set_defaults(func=cmd_play)

    recover = sub.add_parser("bag-recover", help="rebuild a readable bag from an MCAP recording that was killed")
    recover.add_argument("bag", help="the broken bag folder (or its .mcap file)")
    recover.add_argument("output", help="new bag folder")
    recover.set_defaults(func=cmd_bag_recover)


def cmd_record(args: argparse.Namespace) -> int:
    from pathlib import Path

    from ..bags import topic_name_problem
    from ..ros.record_node import main as record_main

    if args.all and args.topics:
        raise CliError(f"--all records every topic on the graph; give the topics ({' '.join(args.topics)}) or "
                       "--all, not both", EXIT_USAGE)
    for topic in args.topics or ():  # said before ROS starts, not as an RCLError from inside it
        problem = topic_name_problem(topic)
        if problem:
            raise CliError(problem, EXIT_USAGE)
    if args.output:
        output = Path(args.output)
        if output.exists() or output.is_symlink():
            raise CliError(f"-o {args.output} exists already; a recording never overwrites a bag or a file",
                           EXIT_USAGE)
        check_writable([("-o", args.output, True)], "recorded")

    ros_args = ["--ros-args", "-p", f"storage:={args.storage}"]
    if args.output:
        ros_args += ["-p", f"output:={args.output}"]
    if args.topics:  # none named (or --all): the node's own DEFAULT_TOPICS, the one list of them
        ros_args += ["-p", "topics:=[" + ",".join(f"'{t}'" for t in args.topics) + "]"]
    ros_args += ["-p", f"all:={'true' if args.all else 'false'}", "-p", f"duration:={float(args.duration or 0.0)}"]
    return record_main(["veg-area-record", *ros_args])

def cmd_play(args: argparse.Namespace) -> int:
    from ..bags import BagError, play_topics
    from ..ros.play_node import main as play_main

    try:
        play_topics(args.bag, args.topics)  # a clear error before ROS starts
    except BagError as exc:
        raise CliError(str(exc)) from exc
    if args.delay < 0 or args.wait_for_subscribers < 0:
        raise CliError("--delay and --wait-for-subscribers must be 0 or more", EXIT_USAGE)
    ros_args = ["--ros-args", "-p", f"bag:={args.bag}", "-p", f"rate:={args.rate}", "-p", f"delay:={args.delay}",
                "-p", f"wait_for_subscribers:={float(args.wait_for_subscribers)}"]
    if args.topics:
        ros_args += ["-p", "topics:=[" + ",".join(f"'{t}'" for t in args.topics) + "]"]
    return play_main(["veg-area-play", *ros_args])

def cmd_bag_recover(args: argparse.Namespace) -> int:
    from ..bags import BagError, recover_bag

    try:
        recovery = recover_bag(args.bag, args.output)
    except BagError as exc:
        raise CliError(str(exc)) from exc
    for topic, count in recovery.counts.items():
        print(f"{topic}: {count} messages recovered")
    for reason in recovery.dropped:
        print(f"damaged: {reason}", file=sys.stderr)
    if recovery.unchecked_chunks:
        print(f"{recovery.unchecked_chunks} chunk(s) carry no CRC (the writer computed none): damage inside them "
              "cannot be detected", file=sys.stderr)
    print(f"readable bag: {args.output}" + (f" ({len(recovery.dropped)} damaged part(s) left out)"
                                           if recovery.dropped else ""))
    return 0
