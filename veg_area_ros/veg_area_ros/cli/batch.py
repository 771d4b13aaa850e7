"""`veg-area measure --jobs N` over several inputs: each input (video, bag, image or folder) measured by its
own worker process, N at a time, with one progress line; a CSV + plot per input and batch_summary.csv."""

from __future__ import annotations

import contextlib
import json
import multiprocessing
import os
import queue
import signal
import sys
import threading
import time
import traceback
from concurrent.futures import FIRST_COMPLETED, CancelledError, ProcessPoolExecutor, wait
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

from ..files import FileWriteError
from ..series import series_summary
from .common import (
    EXIT_FAILED,
    EXIT_INTERRUPTED,
    EXIT_OK,
    EXIT_USAGE,
    CliError,
    check_outputs,
    check_writable,
    progress,
    write_csv,
)
from .measure_job import MeasureJob, frames_lost, measure

if TYPE_CHECKING:
    from concurrent.futures import Future
    from multiprocessing.context import BaseContext
    from multiprocessing.managers import SyncManager

# mean_area_std_m2: the uncertainty of the mean Af; frame_spread_m2: the frames' standard deviation (series.py)
BATCH_COLUMNS = ("input", "frames", "measured", "mean_area_m2", "mean_area_std_m2", "frame_spread_m2", "warnings",
                 "not_measured", "csv", "error")
PROGRESS_EVERY_S = 2.0
PR_SET_PDEATHSIG = 1  # prctl option: the signal a process gets when its parent dies


def batch_csv_paths(inputs: list[str], folder: Path) -> list[Path]:
    """<stem>_area.csv per input; inputs sharing a stem are told apart by their position, and a name that
    still meets another (clip.avi and sub/clip.avi numbered 01_, 02_ beside an input named 01_clip.avi) gets
    a further number: every input its own file."""
    stems = [Path(i.rstrip("/")).stem or "input" for i in inputs]
    names = [f"{k + 1:02d}_{stem}_area.csv" if stems.count(stem) > 1 else f"{stem}_area.csv"
             for k, stem in enumerate(stems)]
    taken: set[str] = set()
    unique = []
    for name in names:
        candidate, extra = name, 2
        while candidate in taken or (candidate != name and candidate in names):
            candidate = name.replace("_area.csv", f"_{extra}_area.csv")
            extra += 1
        taken.add(candidate)
        unique.append(folder / candidate)
    return unique


def _ignore_ctrl_c() -> None:
    """Batch workers leave Ctrl-C to the main process, which asks them to stop between frames: interrupted
    anywhere (an idle worker, one writing its CSV), a worker would break the pool and lose the others' work.
    And they end with it: a main process killed outright (SIGKILL, the OOM killer) takes its workers along
    (Linux's parent-death signal) instead of leaving them measuring to the end for nobody."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if sys.platform.startswith("linux"):
        import ctypes

        with contextlib.suppress(OSError, AttributeError):
            ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL)


class CtrlCWhileStarting:
    """Ctrl-C ignored while the batch's processes start, until `started()`: they begin with it ignored (exec
    keeps an ignored signal, and Python then leaves it so). A worker interrupted while importing, before its
    initializer, broke the pool and lost the other's work; a blocked mask did not carry over (spawning a process
    cleared it). A Ctrl-C within these few hundred milliseconds is not seen: blocking it in this thread as well
    does not hold it, since another thread (OpenCV's: 4 at a batch's start) takes the signal and drops it."""

    def __enter__(self) -> CtrlCWhileStarting:
        self.previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
        return self

    def started(self) -> None:
        signal.signal(signal.SIGINT, self.previous)

    def __exit__(self, *exc) -> None:
        self.started()


def _summary(source: str, csv_path: str, error: str = "") -> dict:
    """One input's row of batch_summary.csv before anything was measured."""
    return {"input": source, "frames": 0, "measured": 0, "mean_area_m2": "", "mean_area_std_m2": "",
            "frame_spread_m2": "", "warnings": "", "not_measured": "", "csv": csv_path, "error": error}


def _started_manager(context: BaseContext) -> SyncManager:
    """The batch's manager process (the progress queue, the stop flag), begun as the workers are: Ctrl-C left to
    the main process, and ending with it."""
    from multiprocessing.managers import SyncManager

    manager = SyncManager(ctx=context)
    manager.start(_ignore_ctrl_c)
    return manager


def _measure_one(job: MeasureJob, position: int, progress_queue: queue.Queue, stopping: threading.Event) -> dict:
    """Input number `position` of a batch, in a worker process: its CSV and plot, and a one-line summary."""
    source, csv_path = job.inputs[0], job.csv
    try:
        code, rows = measure(job, on_frame=lambda index, total: progress_queue.put((position, index, total)),
                             stop=stopping.is_set)
    except CliError as exc:
        return _summary(source, csv_path, str(exc))
    return input_summary(source, csv_path, code, rows)


def input_summary(source: str, csv_path: str, code: int, rows: list[dict]) -> dict:
    """One input's row of batch_summary.csv from its measured rows and its run's exit code."""
    summary = _summary(source, csv_path)
    if code == EXIT_INTERRUPTED:
        summary["error"] = f"interrupted after {len(rows)} frames"
    elif code == EXIT_FAILED:
        summary["error"] = frames_lost(rows) or "no object found in any frame"
    series = series_summary(rows)
    summary.update({key: series[key] for key in ("frames", "measured", "warnings", "not_measured")})
    if series["measured"]:
        summary.update({key: series[key] for key in ("mean_area_m2", "mean_area_std_m2", "frame_spread_m2")})
    return summary


def _outcome(future: Future, source: str, csv_path: str) -> dict:
    """A worker's summary; a worker that never began or that crashed is a row that says so."""
    try:
        return future.result()
    except CancelledError:
        return _summary(source, "", "interrupted before it began")
    except FileWriteError as exc:  # a full disk: its rows up to then are in its CSV
        return _summary(source, csv_path, f"{exc}; the rows written before it stay")
    except Exception as exc:  # a bug or a killed worker: its input failed, the others go on
        detail = "".join(traceback.format_exception_only(exc)).strip()
        return _summary(source, csv_path, f"worker failed: {detail}")


def check_batch(job: MeasureJob, folder: Path) -> list[str]:
    """Refuse (exit 2, before any work) what does not apply to a batch, would be written over an input or
    cannot be written; the per-input CSV paths."""
    if job.csv:
        raise CliError("--csv names one file; a batch writes <input>_area.csv per input into --output-dir",
                       EXIT_USAGE)
    if job.idealized:
        raise CliError("--idealized is for one input at a time (frames of several inputs would mix)", EXIT_USAGE)
    if job.overlay and Path(job.overlay).suffix.lower() in (".png", ".jpg", ".jpeg"):
        raise CliError(f"--overlay {job.overlay} names one image; give a folder for a batch", EXIT_USAGE)
    inputs = list(job.inputs)
    sources = [*inputs, job.calibration if job.calibration.lower() not in ("none", "bag") else None, job.targets,
               job.background]
    # the folder gets each input's CSV and its plot (PNG); the overlay folder images
    check_outputs([("--output-dir", str(folder), True), ("--overlay", job.overlay, True),
                   *(("--output-dir", str(path), True) for path in batch_csv_paths(inputs, folder))], sources,
                  "measured")
    check_writable([("--output-dir", folder, True)], "measured")
    return [str(path) for path in batch_csv_paths(inputs, folder)]  # by position: an input may come twice


def input_job(job: MeasureJob, source: str, csv_path: str) -> MeasureJob:
    """The batch's job for one of its inputs, writing into its own CSV (and overlay folder)."""
    return replace(job, inputs=(source,), csv=csv_path, json=False, quiet=True,
                   overlay=str(Path(job.overlay) / Path(csv_path).stem) if job.overlay else None)


def finish_batch(job: MeasureJob, folder: Path, rows: list[dict], interrupted: bool) -> int:
    """batch_summary.csv, a line (or JSON object) per input, and the exit code of the whole batch."""
    say = progress(job.quiet)
    summary_path = folder / "batch_summary.csv"
    write_csv(summary_path, BATCH_COLUMNS, rows)
    for row in rows:
        if job.json:  # one object per input (the frames are in its CSV)
            print(json.dumps(row), flush=True)
            continue
        mean = (f"Af = {row['mean_area_m2']:.6g} ± {row['mean_area_std_m2']:.2g} m² (mean of {row['measured']} of "
                f"{row['frames']} frames and its uncertainty; frame-to-frame sd {row['frame_spread_m2']:.2g} m²)"
                if row["measured"] else f"not measured: {row['error'] or 'no frame measured'}")
        print(f"{row['input']}: {mean}", flush=True)
    say(f"batch summary: {summary_path}")
    if interrupted:
        say("batch interrupted: what each input measured so far is in its CSV")
        return EXIT_INTERRUPTED
    failed = [row["input"] for row in rows if not row["measured"]]
    if failed:
        raise CliError(f"{len(failed)} of {len(rows)} inputs gave no measurement: {', '.join(failed)}")
    damaged = [row["input"] for row in rows if row["error"]]
    if damaged:
        raise CliError(f"{len(damaged)} of {len(rows)} inputs lost frames (unreadable, or the cluster measuring "
                       f"them was lost): {', '.join(damaged)} (see batch_summary.csv)")
    return EXIT_OK


def measure_batch(job: MeasureJob, jobs: int, folder: Path) -> int:
    csv_paths = check_batch(job, folder)
    inputs = list(job.inputs)
    folder.mkdir(parents=True, exist_ok=True)
    workers = min(jobs or os.cpu_count() or 1, len(inputs))
    context = multiprocessing.get_context("spawn")  # workers start clean (OpenCV threads, no forked state)
    say = progress(job.quiet)
    say(f"batch: {len(inputs)} inputs, {workers} at a time")
    # Ctrl-C and SIGTERM set a flag that the loop reads between its steps: raised as KeyboardInterrupt they could
    # land inside a call to the manager (its reply half read), and the next call on that connection would hang
    stop = threading.Event()
    handlers = catch_stop_signals(stop)
    summaries: dict[int, dict] = {}
    interrupted = False
    try:
        with (CtrlCWhileStarting() as starting, _started_manager(context) as manager,
              ProcessPoolExecutor(workers, mp_context=context, initializer=_ignore_ctrl_c) as pool):
            progress_queue, stopping = manager.Queue(), manager.Event()
            pending = {}
            for k, source in enumerate(inputs):
                pending[pool.submit(_measure_one, input_job(job, source, csv_paths[k]), k, progress_queue,
                                    stopping)] = k
            starting.started()  # every worker is started by its submit
            done_frames: dict[int, tuple[int, int]] = {}
            last_line = 0.0
            while pending and not stop.is_set():
                finished, _ = wait(pending, timeout=0.5, return_when=FIRST_COMPLETED)
                for future in finished:
                    k = pending.pop(future)
                    summaries[k] = _outcome(future, inputs[k], csv_paths[k])
                    state = summaries[k]["error"] or f"{summaries[k]['measured']} frames measured"
                    say(f"batch: {inputs[k]} done: {state}")
                with contextlib.suppress(queue.Empty):
                    while True:
                        k, index, total = progress_queue.get_nowait()
                        done_frames[k] = (index, total)
                if time.monotonic() - last_line > PROGRESS_EVERY_S and pending and done_frames:
                    frames = sum(i for i, _ in done_frames.values())
                    total = sum(t for _, t in done_frames.values())
                    say(f"batch: {len(summaries)}/{len(inputs)} inputs done; {frames} of {total} frames "
                        "measured in the inputs begun")
                    last_line = time.monotonic()
            if pending:  # stopped: the workers stop after their current frame and keep what they measured
                interrupted = True
                stopping.set()
                for future in pending:
                    future.cancel()
                for future, k in pending.items():
                    summaries[k] = _outcome(future, inputs[k], csv_paths[k])
    finally:
        restore_signals(handlers)
    return finish_batch(job, folder, [summaries[k] for k in range(len(inputs))], interrupted)


def catch_stop_signals(stop: threading.Event) -> dict:
    """SIGINT and SIGTERM set `stop` (in the main thread; elsewhere they stay as they are); the handlers they
    replace, for `restore_signals`."""
    if threading.current_thread() is not threading.main_thread():
        return {}
    return {number: signal.signal(number, lambda *_: stop.set()) for number in (signal.SIGINT, signal.SIGTERM)}


def restore_signals(handlers: dict) -> None:
    for number, handler in handlers.items():
        signal.signal(number, handler)
