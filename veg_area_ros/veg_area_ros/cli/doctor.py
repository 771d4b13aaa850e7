"""`veg-area doctor`: checks what makes a lab PC fail silently and prints each problem with its fix."""

from __future__ import annotations

import argparse
import json
import os
from dataclasses import asdict
from pathlib import Path

from .common import EXIT_FAILED, EXIT_OK


def add_parser(sub: argparse._SubParsersAction) -> None:
    doctor = sub.add_parser("doctor", help="check this PC for what makes ROS nodes or videos fail silently "
                            "(rclpy, transport profile, socket buffers, /dev/shm, ROS_* settings, ament index, "
                            "video backends); each problem with its fix")
    doctor.add_argument("--json", action="store_true", help="the findings as one JSON object")
    # another root's files, to check a mounted system image (and for the tests' made-up problems)
    doctor.add_argument("--sysctl-dir", type=Path, default=Path("/proc/sys/net/core"), help=argparse.SUPPRESS)
    doctor.add_argument("--shm-dir", type=Path, default=Path("/dev/shm"), help=argparse.SUPPRESS)
    doctor.set_defaults(func=cmd_doctor)


def cmd_doctor(args: argparse.Namespace) -> int:
    from ..doctor import diagnose

    findings = diagnose(dict(os.environ), args.sysctl_dir, args.shm_dir)
    problems = [f for f in findings if not f.ok]
    if args.json:
        print(json.dumps({"problems": len(problems), "findings": [asdict(f) for f in findings]}, indent=1))
    else:
        for finding in findings:
            print("\n".join(finding.lines()))
        print(f"{len(problems)} problem(s)" if problems else "no problems found")
    return EXIT_FAILED if problems else EXIT_OK
