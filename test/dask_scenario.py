"""A Dask cluster on loopback (a `dask scheduler` and two `dask worker` processes, as a lab starts them) and
`veg-area measure --scheduler` runs against it; run by test_cluster.py inside the tests' network confinement.

    python dask_scenario.py WORKDIR   (writes WORKDIR/scenario.json)

Each step's exit code, stderr and timing go into the JSON; the test compares the files the runs wrote."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

PYTHON = sys.executable
MEASURE = ["measure", "--calibration", "cal.yaml", "--targets", "targets.yaml", "--threshold", "120"]


def start(command: list[str], log: Path) -> subprocess.Popen:
    return subprocess.Popen(command, stdout=log.open("w"), stderr=subprocess.STDOUT, start_new_session=True)


def veg_area(*args: str, **popen) -> subprocess.CompletedProcess | subprocess.Popen:
    command = [PYTHON, "-m", "veg_area_ros.cli", *args]
    if popen:
        return subprocess.Popen(command, text=True, **popen)
    return subprocess.run(command, capture_output=True, text=True, timeout=600)


def start_scheduler(workdir: Path, name: str) -> tuple[subprocess.Popen, str]:
    """A `dask scheduler` on loopback (any free port); its process and address, read from its scheduler file."""
    scheduler = start([PYTHON, "-m", "dask", "scheduler", "--host", "127.0.0.1", "--port", "0",
                       "--scheduler-file", f"{name}.json", "--no-dashboard"], workdir / f"{name}.log")
    deadline = time.monotonic() + 60
    while not (workdir / f"{name}.json").exists() and time.monotonic() < deadline:
        time.sleep(0.2)
    return scheduler, json.loads((workdir / f"{name}.json").read_text())["address"]


def start_worker(workdir: Path, scheduler: str, name: str) -> subprocess.Popen:
    return start([PYTHON, "-m", "dask", "worker", "--scheduler-file", f"{scheduler}.json", "--nthreads", "1",
                  "--no-nanny", "--no-dashboard", "--host", "127.0.0.1", "--name", name], workdir / f"{name}.log")


def step(done: subprocess.CompletedProcess, seconds: float) -> dict:
    return {"code": done.returncode, "stderr": done.stderr[-4000:], "stdout": done.stdout[-4000:],
            "seconds": seconds}


def main(workdir: Path) -> None:
    os.chdir(workdir)
    results: dict = {}
    processes: list[subprocess.Popen] = []
    try:
        scheduler, address = start_scheduler(workdir, "scheduler")
        processes.append(scheduler)
        workers = [start_worker(workdir, "scheduler", f"w{k}") for k in range(2)]
        processes += workers
        from distributed import Client

        with Client(address, timeout=30) as client:
            client.wait_for_workers(2, timeout=60)
        results["address"] = address
        videos = [f"v{k}.avi" for k in range(6)]

        started = time.monotonic()
        results["six"] = step(veg_area(*MEASURE, *videos, "--scheduler", address, "--output-dir", "cluster_six"),
                              time.monotonic() - started)

        started = time.monotonic()
        results["long"] = step(veg_area(*MEASURE, "long.avi", "--segment-frames", "10", "--scheduler", address,
                                        "--output-dir", "cluster_long"), time.monotonic() - started)

        started = time.monotonic()
        results["missing"] = step(veg_area(*MEASURE, "v0.avi", "not_on_the_workers.avi", "--scheduler", address,
                                           "--output-dir", "cluster_missing"), time.monotonic() - started)

        # listeners that are not Dask: one silent, one with an SSH server's banner; each refused in one line
        import socket
        import threading

        def listener(banner: bytes) -> int:
            server = socket.create_server(("127.0.0.1", 0))

            def serve() -> None:
                while True:
                    connection, _ = server.accept()
                    if banner:
                        connection.sendall(banner)
                    time.sleep(30)  # held open and silent, as a hung service would
                    connection.close()

            threading.Thread(target=serve, daemon=True).start()
            return server.getsockname()[1]

        for name, banner in (("silent", b""), ("ssh", b"SSH-2.0-OpenSSH_9.2p1 Debian-2\r\n")):
            port = listener(banner)
            results[f"not_dask_{name}"] = step(veg_area(*MEASURE, "v0.avi", "--scheduler", f"tcp://127.0.0.1:{port}",
                                                        "--output-dir", f"cluster_{name}"), 0.0)

        started = time.monotonic()
        results["unreachable"] = step(veg_area(*MEASURE, "v0.avi", "--scheduler", "tcp://127.0.0.1:9",
                                               "--output-dir", "cluster_unreachable"), time.monotonic() - started)

        # Ctrl-C after the first input is done: finished inputs kept, the rest cancelled (the long one: 120
        # frames in 60 segments, many seconds of work after the short one is done)
        client_run = veg_area(*MEASURE, "v0.avi", "longer.avi", "--segment-frames", "2", "--scheduler", address,
                              "--output-dir", "cluster_interrupted", stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        lines = []
        for line in client_run.stderr:
            lines.append(line)
            if " done: " in line:
                client_run.send_signal(signal.SIGINT)
                break
        out, err = client_run.communicate(timeout=120)
        results["interrupted"] = {"code": client_run.returncode, "stderr": "".join(lines) + err}

        # a worker SIGKILLed after the first result: its tasks run again on the other, the batch completes
        client_run = veg_area(*MEASURE, *videos, "--scheduler", address, "--output-dir", "cluster_killed",
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        lines, killed = [], False
        for line in client_run.stderr:
            lines.append(line)
            if " done: " in line and not killed:
                workers[1].kill()
                killed = True
        out, err = client_run.communicate(timeout=300)
        results["killed"] = {"code": client_run.returncode, "stderr": "".join(lines) + err, "stdout": out,
                             "worker_killed": killed, "worker_exit": workers[1].wait(timeout=30)}

        # a second cluster: first a scheduler without workers (said, nothing submitted), then one worker, and
        # the scheduler SIGKILLed while a long input is being measured
        lonely, lonely_address = start_scheduler(workdir, "lonely")
        processes.append(lonely)
        results["no_workers"] = step(veg_area(*MEASURE, "v0.avi", "--scheduler", lonely_address, "--output-dir",
                                              "cluster_no_workers"), 0.0)
        processes.append(start_worker(workdir, "lonely", "w_lonely"))
        client_run = veg_area(*MEASURE, "v0.avi", "longer.avi", "--segment-frames", "2", "--scheduler",
                              lonely_address, "--output-dir", "cluster_lost", stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE)
        lines = []
        for line in client_run.stderr:
            lines.append(line)
            if " done: " in line:
                os.killpg(lonely.pid, signal.SIGKILL)
                break
        out, err = client_run.communicate(timeout=300)
        results["scheduler_lost"] = {"code": client_run.returncode, "stderr": "".join(lines) + err, "stdout": out}
    finally:
        for process in reversed(processes):
            if process.poll() is None:
                os.killpg(process.pid, signal.SIGTERM)
        for process in processes:
            try:
                process.wait(timeout=20)
            except subprocess.TimeoutExpired:
                os.killpg(process.pid, signal.SIGKILL)
                process.wait()
        (workdir / "scenario.json").write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main(Path(sys.argv[1]))
