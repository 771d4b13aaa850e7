"""`veg-area measure INPUTS... --scheduler ADDRESS`: the inputs measured on a Dask cluster's workers with the
same measurement job as on this machine. A video or bag is split into its segments (`--segment-frames`, each
begun afresh whoever measures it), so one long video uses many workers and its rows are identical to measuring
it whole. Tasks return rows and write nothing (a task that Dask runs again after its worker died repeats no
write); this client writes each input's CSV and plot, batch_summary.csv and the summary lines, as `--jobs`."""

from __future__ import annotations

import threading
import time
from dataclasses import replace
from pathlib import Path

from .batch import _summary, catch_stop_signals, check_batch, finish_batch, input_job, input_summary, restore_signals
from .common import EXIT_FAILED, EXIT_OK, EXIT_USAGE, CliError, progress, write_csv
from .measure_job import CSV_COLUMNS, MeasureJob, csv_row, frames_lost, measure, no_object_anywhere, plot_series

CONNECT_TIMEOUT_S = 6  # the whole refusal within 10 s, the interpreter and its imports included
PROGRESS_EVERY_S = 2.0


def input_frames(job: MeasureJob) -> int | None:
    """On a worker: the frames (indices) of the job's one input when it is a video or bag, else None (images
    and folders are one task). Raises CliError when the worker cannot open it."""
    from ..bags import BagError, bag_image_count
    from ..frames import VIDEO_SUFFIXES, InputError, expand_inputs, is_bag, video_frame_count

    try:
        files = expand_inputs(list(job.inputs))
        if len(files) == 1 and is_bag(files[0]):
            return bag_image_count(files[0], job.image_topic)
        if len(files) == 1 and files[0].suffix.lower() in VIDEO_SUFFIXES:
            count = video_frame_count(files[0])
            if count <= 0:
                raise InputError(f"{files[0]}: is not a video OpenCV can open")
            return count
    except (InputError, BagError) as exc:
        raise CliError(str(exc)) from exc
    return None


def measure_part(job: MeasureJob) -> list[dict]:
    """On a worker: the rows of the job's one input (or its frame range). Writes nothing."""
    return measure(job, on_frame=lambda index, total: None, part=True)[1]


def segments(frames: int, size: int) -> list[tuple[int, int]]:
    """Frame ranges that start at segment boundaries: the same rows as one pass over the input."""
    return [(start, min(start + size, frames)) for start in range(0, frames, size)] or [(0, 0)]


def scheduler_address(text: str) -> tuple[str, str, int]:
    """A Dask scheduler's address checked at once: (tcp://HOST:PORT, host, port); CliError (exit 2) naming what
    is wrong with it. HOST:PORT alone is taken as tcp; a pasted dashboard URL (http://HOST:8787/status) is
    recognised and the scheduler's usual address suggested."""
    from urllib.parse import urlsplit

    given = text.strip()
    parts = urlsplit(given if "://" in given else f"tcp://{given}")
    scheme = parts.scheme.lower()
    try:
        port = parts.port
    except ValueError:
        port = None
        text_port = parts.netloc.rsplit(":", 1)[-1]
        raise CliError(f"--scheduler {given}: the port {text_port!r} is not a number from 1 to 65535",
                       EXIT_USAGE) from None
    host = parts.hostname or ""
    if scheme in ("http", "https"):
        raise CliError(f"--scheduler {given} is a web address (Dask's dashboard, port 8787 by default); the "
                       f"scheduler itself listens at tcp://{host or 'HOST'}:8786", EXIT_USAGE)
    if scheme != "tcp":
        raise CliError(f"--scheduler {given}: the scheme {scheme}:// is not one this command speaks (tcp://HOST:PORT"
                       f"{'; tls needs certificates it does not take' if scheme == 'tls' else ''})", EXIT_USAGE)
    if not host or port is None or not 0 < port < 65536 or parts.path not in ("", "/"):
        raise CliError(f"--scheduler {given}: give it as tcp://HOST:PORT (tcp://head:8786)", EXIT_USAGE)
    return f"tcp://{host}:{port}", host, port


def _connect(address: str):
    address, host, port = scheduler_address(address)
    import socket

    try:  # a closed port or an unknown host said at once, before Dask's own retries
        socket.create_connection((host, port), timeout=CONNECT_TIMEOUT_S).close()
    except OSError as exc:
        raise CliError(f"the Dask scheduler at {address} cannot be reached ({exc.strerror or exc}); nothing was "
                       "measured") from None
    try:
        from distributed import Client
    except ImportError as exc:  # optional on a ROS install (rosdep does not bring it)
        raise CliError("--scheduler needs dask's distributed package: pip install -r requirements.txt") from exc

    try:
        return Client(address, timeout=CONNECT_TIMEOUT_S, set_as_default=False)
    except (OSError, TimeoutError) as exc:
        raise CliError(f"the Dask scheduler at {address} cannot be reached ({exc}); nothing was measured") from exc


def measure_on_cluster(job: MeasureJob, address: str, folder: Path) -> int:
    if job.frame_range is not None:
        raise CliError("a frame range is the cluster's own unit; give whole inputs")
    csv_paths = check_batch(job, folder)
    inputs = list(job.inputs)
    say = progress(job.quiet)
    client = _connect(address)
    from distributed import as_completed

    folder.mkdir(parents=True, exist_ok=True)
    workers = len(client.scheduler_info(n_workers=-1).get("workers", {}))
    say(f"cluster {address}: {len(inputs)} inputs, {workers} workers")
    jobs = [input_job(job, source, csv_paths[k]) for k, source in enumerate(inputs)]
    parts: dict[int, dict[int, list[dict]]] = {k: {} for k in range(len(inputs))}
    expected: dict[int, int] = {}  # input -> number of parts
    frames_of: dict[int, int | None] = {}
    summaries: dict[int, dict] = {}
    pending: dict = {}
    started, last_line, frames_done = time.monotonic(), 0.0, 0
    for k, one in enumerate(jobs):
        future = client.submit(input_frames, one, pure=False, priority=len(inputs),
                               key=f"veg-area-count-{k}-{time.time_ns()}")
        pending[future] = ("count", k, 0)
    counting = as_completed(list(pending), loop=client.loop)
    interrupted = False

    def finish(k: int) -> None:
        rows = [row for part in sorted(parts[k]) for row in parts[k][part]]
        code = EXIT_FAILED if frames_lost(rows) or no_object_anywhere(rows) else EXIT_OK
        measured = [r for r in rows if not r["error"]]
        if rows:
            path = Path(csv_paths[k])
            write_csv(path, CSV_COLUMNS, [csv_row(row) for row in rows])
            if len(rows) > 1:
                plot_series(rows, path)
        summaries[k] = input_summary(inputs[k], csv_paths[k] if rows else "", code, rows)
        if not measured and not summaries[k]["error"]:
            summaries[k]["error"] = "; ".join(sorted({r["error"] for r in rows}))[:500] or "no frame"
        say(f"cluster: {inputs[k]} done: {summaries[k]['error'] or str(summaries[k]['measured']) + ' frames measured'}")

    # Ctrl-C and SIGTERM set a flag that the loop reads between results: raised as KeyboardInterrupt they can
    # land inside Dask's own code (a Future's __del__ swallows it), and the interrupt would be lost
    stop = threading.Event()
    handlers = catch_stop_signals(stop)
    try:
        while not counting.is_empty() and not stop.is_set():
            if not counting.has_ready():
                stop.wait(0.05)
                continue
            for future in counting.next_batch(block=False):
                kind, k, part = pending.pop(future)
                if k in summaries:
                    continue
                try:
                    result = future.result()
                except Exception as exc:  # the input cannot be opened where it runs, a bug, a worker lost thrice
                    summaries[k] = _summary(inputs[k], "", _reason(exc))
                    say(f"cluster: {inputs[k]} failed: {summaries[k]['error']}")
                    continue
                if kind == "count":
                    frames_of[k] = result
                    ranges = segments(result, job.segment_frames) if result is not None else [None]
                    expected[k] = len(ranges)
                    for part, frame_range in enumerate(ranges):  # earlier inputs first: their files come first
                        task = client.submit(measure_part, replace(jobs[k], frame_range=frame_range), pure=False,
                                             priority=-k, key=f"veg-area-part-{k}-{part}-{time.time_ns()}")
                        pending[task] = ("part", k, part)
                        counting.add(task)
                    continue
                parts[k][part] = result
                frames_done += len(result)
                if len(parts[k]) == expected[k]:
                    finish(k)
            now = time.monotonic()
            if now - last_line > PROGRESS_EVERY_S and len(summaries) < len(inputs):
                known = sum(f for f in frames_of.values() if f is not None)
                rate = frames_done / max(now - started, 1e-9)
                left = f", about {max(known - frames_done, 0) / rate:.0f} s left" if rate > 0 and known else ""
                say(f"cluster: {len(summaries)}/{len(inputs)} inputs done; {frames_done} frames measured, "
                    f"{rate:.1f} frames/s{left}")
                last_line = now
        if stop.is_set():  # cancel what is left; every input finished so far is kept
            interrupted = True
            client.cancel(list(pending))
    finally:
        client.close()
        restore_signals(handlers)
    return finish_batch(job, folder, [summaries.get(k) or _summary(inputs[k], "", "interrupted before it finished")
                                      for k in range(len(inputs))], interrupted)


def _reason(exc: BaseException) -> str:
    text = str(exc) or type(exc).__name__
    if type(exc).__name__ == "KilledWorker":
        return f"its task's workers died repeatedly ({text})"
    return text.splitlines()[0][:500] if not isinstance(exc, CliError) else text
