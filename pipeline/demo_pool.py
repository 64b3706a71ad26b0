"""The demo's worker processes: independent steps run side by side, in as few processes as
the cores, each keeping torch and the code loaded from one step to the next.

A worker is started (``spawn``) with its share of the cores (``workers x threads = cores``:
its torch and BLAS threads set before either loads) and then runs one step at a time as
``pipeline -q ARGS`` does in a process of its own: the same click command, so the same
options, the same runner (``run_train`` for a training run) and the same refusals (one line,
exit status 2). Each step's stdout is dropped and its stderr kept, to be shown when it fails.
The same seeds give the same weights as a process of their own with as many threads.

:class:`Pool` hands out the steps of a batch as each one's inputs are written (no pending
step of the batch writes one of them: a fine-tuning waits for its pre-training), at most one
per worker; the first step to fail stops the others (their workers are killed) and the demo,
with that step's message and exit status.
"""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
import time
import traceback
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from multiprocessing import connection, get_context
from multiprocessing.process import BaseProcess
from pathlib import Path
from typing import IO, Any

import click

from core.bounds import Bound
from pipeline.demo_plan import Step

WORKERS = Bound(1, whole=True)   # a pool's processes
THREAD_VARIABLES = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")
# what ``python -m pipeline`` has as sys.argv[0]: the provenance records the command line
MAIN = str(Path(__file__).with_name("__main__.py"))


@dataclass(frozen=True)
class StepResult:
    """How a step ended: exit status, its stderr, and its wall time in the worker (s)."""

    rc: int
    log: str
    seconds: float
    worker: int = -1


def ready(step: Step, pending: list[Step]) -> bool:
    """Whether no pending step (waiting or running) writes one of ``step``'s inputs."""
    return not any(set(step.inputs) & set(other.outputs) for other in pending)


# -- in the worker ------------------------------------------------------------------------------

def set_threads(threads: int) -> None:
    """Give this process ``threads`` threads for torch and the BLAS (before they load)."""
    for name in THREAD_VARIABLES:
        os.environ[name] = str(threads)
    import torch

    torch.set_num_threads(threads)


def run_step(args: tuple[str, ...]) -> StepResult:
    """``pipeline -q ARGS`` in this process: its exit status, stderr and wall time."""
    tic = time.perf_counter()
    with tempfile.TemporaryFile("w+") as log:
        with _captured(log):
            rc = _invoke(args)
        log.seek(0)
        return StepResult(rc, log.read(), time.perf_counter() - tic)


def _invoke(args: tuple[str, ...]) -> int:
    """The exit status ``python -m pipeline -q ARGS`` would end with (a traceback on
    stderr for an internal error, as there)."""
    from pipeline.cli import cli

    argv = ["-q", *args]
    sys.argv = [MAIN, *argv]
    try:
        rc = cli.main(argv, prog_name="pipeline", standalone_mode=False)
    except click.ClickException as e:           # a usage error: click's message, status 2
        e.show()
        return e.exit_code
    except click.Abort:
        click.echo("Aborted!", err=True)
        return 1
    except SystemExit as e:
        return e.code if isinstance(e.code, int) else 0 if e.code is None else 1
    except Exception:  # noqa: BLE001 - an internal error: its traceback, status 1
        traceback.print_exc()
        return 1
    return rc if isinstance(rc, int) else 0


@contextlib.contextmanager
def _captured(log: IO[str]) -> Iterator[None]:
    """stdout to nowhere and stderr to ``log``, at the file descriptors (what C code and
    child processes write too), restored after."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = os.dup(1), os.dup(2)
    with open(os.devnull, "w") as null:
        try:
            os.dup2(null.fileno(), 1)
            os.dup2(log.fileno(), 2)
            yield
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            for fd in saved:
                os.close(fd)


def serve(conn: connection.Connection, threads: int) -> None:
    """A worker's life: its threads set and the pipeline loaded, then one step per message
    until it is told to stop (``None``)."""
    set_threads(threads)
    import pipeline.cli  # noqa: F401 - loaded once, as torch is, for every step to come

    while (args := conn.recv()) is not None:
        conn.send(run_step(args))


# -- in the demo --------------------------------------------------------------------------------

@dataclass
class _Worker:
    number: int
    process: BaseProcess
    conn: connection.Connection
    step: Step | None = None


class Pool:
    """Up to ``workers`` processes of ``threads`` threads each, started as steps need them
    and kept for the next batch; close it (``with Pool(...)``) to stop them."""

    def __init__(self, workers: int, threads: int) -> None:
        WORKERS.check("workers", workers)
        self.size, self.threads = workers, threads
        self._workers: list[_Worker] = []
        self._started = 0                 # workers started so far: the next one's number
        self._context = get_context("spawn")

    def __enter__(self) -> Pool:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def run(self, steps: list[Step], started: Callable[[Step, int], None],
            done: Callable[[Step, StepResult], None]) -> None:
        """Run ``steps``, each as soon as its inputs are written and a worker is free;
        ``started`` and ``done`` are told of each. A failing step kills the others and ends
        the demo (``SystemExit`` with its status) after its stderr is shown."""
        waiting = list(steps)
        while waiting or self._busy():
            self._start_ready(waiting, started)
            if not self._busy():
                raise RuntimeError("demo steps wait on each other: "
                                   + ", ".join(" ".join(s.args[:1]) for s in waiting))
            for worker, step, result in self._finished():
                worker.step = None
                if result.rc != 0:
                    self._fail(result)
                done(step, result)

    def close(self) -> None:
        """Stop every worker: asked first, killed when it does not stop."""
        for w in self._workers:
            with contextlib.suppress(OSError):
                w.conn.send(None)
        for w in self._workers:
            w.process.join(timeout=10)
            if w.process.is_alive():
                w.process.kill()
                w.process.join()
            w.conn.close()
        self._workers = []

    def _busy(self) -> list[_Worker]:
        return [w for w in self._workers if w.step is not None]

    def _running(self) -> list[Step]:
        """The steps the busy workers run."""
        return [w.step for w in self._workers if w.step is not None]

    def _start_ready(self, waiting: list[Step], started: Callable[[Step, int], None]) -> None:
        """Give each free worker the first waiting step whose inputs are written."""
        while waiting:
            pending = waiting + self._running()
            step = next((s for s in waiting if ready(s, [p for p in pending if p is not s])),
                        None)
            worker = self._free() if step is not None else None
            if step is None or worker is None:
                return
            waiting.remove(step)
            started(step, worker.number)
            worker.step = step
            with contextlib.suppress(OSError):     # a worker that died: seen when waited on
                worker.conn.send(step.args)

    def _free(self) -> _Worker | None:
        """An idle worker (one that died idle is let go), a new one when all are busy and
        there is room, else None."""
        self._workers = [w for w in self._workers if w.step is not None or w.process.is_alive()]
        idle = [w for w in self._workers if w.step is None]
        if idle:
            return idle[0]
        if len(self._workers) >= self.size:
            return None
        parent, child = self._context.Pipe()
        process = self._context.Process(target=serve, args=(child, self.threads),
                                        name=f"demo-worker-{self._started}")
        process.start()
        child.close()
        worker = _Worker(self._started, process, parent)
        self._started += 1
        self._workers.append(worker)
        return worker

    def _finished(self) -> list[tuple[_Worker, Step, StepResult]]:
        """Wait for at least one busy worker to answer (or die); each with its step and
        result."""
        busy = self._busy()
        by_handle: dict[Any, _Worker] = {     # each worker by its pipe and its sentinel (an int)
            **{w.conn: w for w in busy}, **{w.process.sentinel: w for w in busy}}
        answered = {by_handle[h].number: by_handle[h] for h in connection.wait(list(by_handle))}
        return [(w, w.step, self._result(w)) for w in answered.values() if w.step is not None]

    @staticmethod
    def _result(worker: _Worker) -> StepResult:
        try:
            result = worker.conn.recv()
        except (EOFError, OSError):       # the worker died (killed, out of memory)
            worker.process.join()
            return StepResult(1, f"error: the worker running it died (exit status "
                                 f"{worker.process.exitcode})", 0.0, worker.number)
        return StepResult(result.rc, result.log, result.seconds, worker.number)

    def _fail(self, result: StepResult) -> None:
        """Kill the other running steps, show the failed one's stderr (its one line for a
        refusal), end the demo with its exit status."""
        for w in self._busy():
            w.process.kill()
            w.process.join()
            w.step = None
        self._workers = [w for w in self._workers if w.process.is_alive()]
        click.echo(result.log.rstrip(), err=True)
        raise SystemExit(result.rc)
