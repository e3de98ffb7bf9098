"""The batch on Dask distributed: a local cluster of worker processes by default, or an existing
cluster's scheduler; one task per file, each run in its own limited process (:mod:`.sandbox`).

Why Dask and not Ray, measured: docs/batch.md. On the local cluster a worker that dies fails the file
it was running at once (``allowed-failures`` 0) and each worker holds one file at a time
(``worker-saturation`` 1.0), so a killed worker costs exactly the file it had; an existing cluster keeps
its scheduler's own settings (Dask's default retries such a file on other workers, three times).
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from cghair_format.errors import CghError, require

from .manifest import Job
from .sandbox import TaskFault, run_limited

LOCAL_CONFIG = {"distributed.scheduler.allowed-failures": 0, "distributed.scheduler.worker-saturation": 1.0}
CONNECT_TIMEOUT = "20s"


@dataclass(frozen=True)
class Limits:
    """Each file's own limits (:func:`.sandbox.run_limited`)."""

    memory_mb: int = 4096  # data memory above the worker's
    seconds: float = 3600.0


def file_task(job: Job, out_dir: Path, limits: Limits) -> dict:
    """The task a worker runs: ``job``'s pipeline in a limited child process; its row, failed or not."""
    from .pipeline import run_file, warm_up

    warm_up()  # in the worker, once, before the first fork: each file's process starts warm
    try:
        return run_limited(run_file, (job, out_dir), limits.memory_mb, limits.seconds)
    except TaskFault as exc:
        return failed_row(job, str(exc))


def failed_row(job: Job, error: str) -> dict:
    return {"input": str(job.rel), "status": "failed", "run": "this", "error": error}


def distributed():
    """The ``distributed`` package, or a one-line error naming the extra that installs it."""
    return require("distributed", "batch", "cgh batch", package="dask[distributed]")


@contextmanager
def connect(scheduler: str | None, workers: int) -> Iterator:
    """A Dask client: of the scheduler at ``scheduler``, else of a local cluster of ``workers`` processes
    (one thread each) on the loopback address."""
    dist = distributed()
    import dask

    if scheduler is not None:
        try:
            client = dist.Client(scheduler, timeout=CONNECT_TIMEOUT)
        except (OSError, TimeoutError, ValueError) as exc:
            raise CghError(f"cannot reach a Dask scheduler at {scheduler} ({' '.join(str(exc).split())}); start "
                           "one (dask scheduler, dask worker ADDRESS) or leave out --scheduler for a local cluster"
                           ) from None
        with client:
            yield client
        return
    with dask.config.set(LOCAL_CONFIG), \
            dist.LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                              dashboard_address=None, memory_limit=0, silence_logs=logging.ERROR) as cluster, \
            dist.Client(cluster) as client:
        yield client


def run_jobs(client, jobs: list[Job], out_dir: Path, limits: Limits, bar) -> list[dict]:
    """Every job's row, run on ``client``'s cluster, largest input first (a long file does not finish last);
    ``bar`` (a tqdm bar, or None) counts them."""
    dist = distributed()
    jobs = sorted(jobs, key=lambda j: -_size(j.input))
    futures = client.map(file_task, jobs, out_dir=out_dir, limits=limits, pure=False,
                         key=[f"cgh-batch-{i}-{os.urandom(4).hex()}" for i in range(len(jobs))])
    job_of = dict(zip((f.key for f in futures), jobs, strict=True))
    rows, failed = [], 0
    try:
        for future in dist.as_completed(futures):
            row = _row(future, job_of[future.key])
            rows.append(row)
            failed += row["status"] != "ok"
            if bar is not None:
                bar.set_postfix(failed=failed, refresh=False)
                bar.update(1)
    finally:
        client.cancel(futures)  # an interrupted run leaves nothing queued on a shared cluster
    return rows


def _size(path: Path) -> int:
    """The file's size; 0 for a missing one, which fails in its task, saying so, while the rest run."""
    try:
        return path.stat().st_size
    except OSError:
        return 0


def _row(future, job: Job) -> dict:
    """The task's row, or a failed row saying why the engine could not give one."""
    try:
        return future.result()
    except Exception as exc:  # noqa: BLE001 - the engine's errors, each that file's alone
        if type(exc).__name__ == "KilledWorker":
            return failed_row(job, "the worker running it died mid-file (killed, or out of memory); nothing of "
                                   "it was recorded as done, and a rerun tries it again")
        return failed_row(job, f"{type(exc).__name__}: {' '.join(str(exc).split())}")


def worker_count(client) -> int:
    return len(client.scheduler_info()["workers"])


def wait_for_workers(client, timeout: float = 60.0) -> int:
    """How many workers the cluster has, once it has one (an error after ``timeout`` seconds)."""
    start = time.monotonic()
    while (count := worker_count(client)) == 0:
        if time.monotonic() - start > timeout:
            raise CghError(f"the Dask cluster has no workers after {timeout:g} s; start some (dask worker ADDRESS)")
        time.sleep(0.2)
    return count
