"""`veg-area measure INPUTS... --scheduler ADDRESS`: the inputs measured on a Dask cluster's workers with the
same measurement job as on this machine. A video or bag is split into its segments (`--segment-frames`, each
begun afresh whoever measures it), so one long video uses many workers and its rows are identical to measuring
it whole. Tasks return rows and write nothing (a task that Dask runs again after its worker died repeats no
write); this client writes each input's CSV and plot, batch_summary.csv and the summary lines, as `--jobs`."""

from __future__ import annotations

import contextlib
import threading
import time
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

from .batch import _summary, catch_stop_signals, check_batch, finish_batch, input_job, input_summary, restore_signals
from .common import EXIT_FAILED, EXIT_OK, EXIT_USAGE, CliError, progress, write_csv
from .measure_job import CSV_COLUMNS, MeasureJob, csv_row, frames_lost, measure, no_object_anywhere, plot_series

if TYPE_CHECKING:
    import socket
    from collections.abc import Callable

    from distributed import Client

CONNECT_TIMEOUT_S = 6  # the whole refusal within 10 s, the interpreter and its imports included
HANDSHAKE_S = 4.0  # a scheduler's handshake comes at once; a listener silent this long is something else
PROGRESS_EVERY_S = 2.0
WORKER_WAIT_S = 30.0  # a cluster without a worker this long (at the start, or all lost) ends the run
SCHEDULER_LOST_S = 10.0  # a scheduler that does not answer this long is lost: what was received is written
ASK_TIMEOUT_S = 5.0  # one question to the scheduler (its workers), so a dead one cannot hold the loop


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


def _check_speaks_dask(connection: socket.socket, address: str) -> None:
    """A Dask scheduler speaks first on a new connection: its handshake, led by its length in bytes as a
    little-endian 64-bit number (a few hundred; text such as SSH's or a web server's banner reads as trillions).
    Something else on that port (a silent listener, a web server, SSH) is refused within HANDSHAKE_S instead of
    hanging in Dask's connect."""
    import struct

    connection.settimeout(HANDSHAKE_S)
    first = b""
    try:
        while len(first) < 8:
            chunk = connection.recv(8 - len(first))
            if not chunk:
                break
            first += chunk
    except TimeoutError:
        raise CliError(f"{address} accepted the connection but said nothing in {HANDSHAKE_S:.0f} s: it is not a "
                       "Dask scheduler (the scheduler listens at tcp://HOST:8786 by default); nothing was "
                       "measured") from None
    except OSError as exc:
        raise CliError(f"the Dask scheduler at {address} cannot be reached ({exc.strerror or exc}); nothing was "
                       "measured") from None
    length = struct.unpack("<Q", first)[0] if len(first) == 8 else 0
    if not 0 < length < 2**24:
        shown = first.decode("ascii", "replace").strip() or "nothing"
        raise CliError(f"{address} is not a Dask scheduler: it answered {shown!r} (the scheduler listens at "
                       "tcp://HOST:8786 by default); nothing was measured")


def _connect(address: str) -> Client:
    address, host, port = scheduler_address(address)
    import socket

    try:  # a closed port or an unknown host said at once, before Dask's own retries
        probe = socket.create_connection((host, port), timeout=CONNECT_TIMEOUT_S)
    except OSError as exc:
        raise CliError(f"the Dask scheduler at {address} cannot be reached ({exc.strerror or exc}); nothing was "
                       "measured") from None
    with probe:
        _check_speaks_dask(probe, address)
    try:
        from distributed import Client
    except ImportError as exc:  # optional on a ROS install (rosdep does not bring it)
        raise CliError("--scheduler needs dask's distributed package: pip install -r requirements.txt") from exc

    try:
        return Client(address, timeout=CONNECT_TIMEOUT_S, set_as_default=False)
    except (OSError, TimeoutError) as exc:
        raise CliError(f"the Dask scheduler at {address} cannot be reached ({exc}); nothing was measured") from exc


def _workers(client: Client) -> int | None:
    """The scheduler's worker count, None when it does not answer within ASK_TIMEOUT_S."""
    try:
        identity = client.sync(client.scheduler.identity, n_workers=-1, callback_timeout=ASK_TIMEOUT_S)
    except Exception:  # a lost connection, a timeout, a closing client: all mean no answer
        return None
    return len(identity.get("workers", {}))


def _wait_for_a_worker(client: Client, address: str, say: Callable[[str], None]) -> int:
    """Workers at the start; CliError when none joins within WORKER_WAIT_S (nothing is submitted then)."""
    deadline = time.monotonic() + WORKER_WAIT_S
    said = False
    while True:
        workers = _workers(client)
        if workers:
            return workers
        if time.monotonic() >= deadline:
            what = "does not answer" if workers is None else "has no workers"
            raise CliError(f"the Dask scheduler at {address} {what} after {WORKER_WAIT_S:.0f} s (start workers with "
                           f"`dask worker {address}`); nothing was measured")
        if not said:
            say(f"cluster {address}: no workers yet, waiting up to {WORKER_WAIT_S:.0f} s for one")
            said = True
        time.sleep(1.0)


def measure_on_cluster(job: MeasureJob, address: str, folder: Path) -> int:
    if job.frame_range is not None:
        raise CliError("a frame range is the cluster's own unit; give whole inputs")
    csv_paths = check_batch(job, folder)
    inputs = list(job.inputs)
    say = progress(job.quiet)
    client = _connect(address)
    _quiet_dask()
    from distributed import as_completed

    try:
        workers = _wait_for_a_worker(client, address, say)
    except CliError:
        client.close()
        raise
    folder.mkdir(parents=True, exist_ok=True)
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
    lost = ""  # why the cluster stopped measuring: the scheduler lost, or no worker left
    answered_at = workers_at = asked_at = time.monotonic()

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
            now = time.monotonic()
            if now - asked_at >= PROGRESS_EVERY_S:  # the scheduler and its workers, between results
                asked_at, workers = now, _workers(client)
                answered_at = now if workers is not None else answered_at
                workers_at = now if workers else workers_at
                if now - answered_at >= SCHEDULER_LOST_S:
                    lost = f"the scheduler at {address} stopped answering for {SCHEDULER_LOST_S:.0f} s"
                    break
                if now - workers_at >= WORKER_WAIT_S:
                    lost = f"the scheduler at {address} had no worker for {WORKER_WAIT_S:.0f} s"
                    break
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
                    if _workers(client) is None:  # the scheduler went away: not this input's fault
                        pending[future] = (kind, k, part)
                        continue
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
        elif pending and not lost:  # every result left came back as the scheduler's loss
            lost = f"the scheduler at {address} was lost"
        if lost:  # what was received is kept: each unfinished input's segments so far, written and said
            say(f"cluster: {lost}; writing what was measured")
            for k in range(len(inputs)):
                if k not in summaries:
                    _write_partial(k, inputs[k], csv_paths[k], parts[k], expected.get(k), lost, summaries)
    finally:
        with contextlib.suppress(Exception):  # a lost scheduler: closing says nothing more
            client.close(timeout=ASK_TIMEOUT_S)
        restore_signals(handlers)
    return finish_batch(job, folder, [summaries.get(k) or _summary(inputs[k], "", "interrupted before it finished")
                                      for k in range(len(inputs))], interrupted)


def _write_partial(k: int, source: str, csv_path: str, parts: dict[int, list[dict]], expected: int | None,
                   lost: str, summaries: dict[int, dict]) -> None:
    """An input the cluster did not finish: its segments received, in order, written as its CSV; its summary
    says how many of how many."""
    rows = [row for part in sorted(parts) for row in parts[part]]
    if rows:
        write_csv(Path(csv_path), CSV_COLUMNS, [csv_row(row) for row in rows])
    summaries[k] = input_summary(source, csv_path if rows else "", EXIT_FAILED, rows)
    summaries[k]["error"] = (f"{lost}: {len(parts)} of {expected if expected is not None else '?'} segments "
                             f"measured ({len(rows)} frames{', written' if rows else ''})")


def _quiet_dask() -> None:
    """Dask's own reconnection tracebacks off stderr: this command says in one line what happened."""
    import logging

    for name in ("distributed", "distributed.client", "distributed.comm", "distributed.batched", "tornado"):
        logging.getLogger(name).setLevel(logging.CRITICAL)


def _reason(exc: BaseException) -> str:
    text = str(exc) or type(exc).__name__
    if type(exc).__name__ == "KilledWorker":
        return f"its task's workers died repeatedly ({text})"
    return text.splitlines()[0][:500] if not isinstance(exc, CliError) else text
