"""Run inside the tests' confinement by test_readme.py: start node commands exactly as given, each with only
the environment given (a newcomer's shell), wait for each to log its transport line, Ctrl-C them all, and print
`RESULT {json}`: per command its exit code, whether the line came, and its output. Always reaps."""

from __future__ import annotations

import json
import shlex
import signal
import subprocess
import sys
import threading
import time


def main() -> int:
    spec = json.loads(sys.argv[1])
    processes, outputs, started = [], [], []
    try:
        for command in spec["commands"]:
            process = subprocess.Popen(shlex.split(command), env=spec["env"], cwd=spec["cwd"], text=True,
                                       stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
            output: list[str] = []
            event = threading.Event()

            def read(process=process, output=output, event=event) -> None:
                for line in process.stdout:
                    output.append(line)
                    if "transport:" in line:
                        event.set()

            threading.Thread(target=read, daemon=True).start()
            processes.append(process)
            outputs.append(output)
            started.append(event)
        deadline = time.monotonic() + spec["timeout"]
        for event, process in zip(started, processes, strict=True):
            while not event.is_set() and process.poll() is None and time.monotonic() < deadline:
                event.wait(0.2)
        time.sleep(spec.get("run_s", 2.0))  # a moment of running together before the Ctrl-C
        alive = [process.poll() is None for process in processes]
        for process in processes:
            if process.poll() is None:
                process.send_signal(signal.SIGINT)
        codes, stopped_after = [], []
        signalled = time.monotonic()
        for process in processes:
            try:  # a minute: CI saw an area node take over 20 s to close on a machine running three graphs at once
                codes.append(process.wait(max(60 - (time.monotonic() - signalled), 1)))
            except subprocess.TimeoutExpired:
                codes.append(None)
            stopped_after.append(round(time.monotonic() - signalled, 1))
    finally:
        for process in processes:
            if process.poll() is None:
                process.kill()
                process.wait()
    time.sleep(0.2)  # the readers' last lines
    print("RESULT " + json.dumps([{"command": c, "transport_logged": e.is_set(), "alive_before_sigint": a,
                                   "exit": code, "stopped_after_s": after, "output": "".join(o)[-4000:]}
                                  for c, e, a, code, after, o in zip(spec["commands"], started, alive, codes,
                                                                     stopped_after, outputs, strict=True)]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
