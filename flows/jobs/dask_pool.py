"""Fan a fleet's voyages out over dask: an existing scheduler, or a local cluster started for the run.

Plain `distributed` futures (no Prefect tasks on workers, so no worker ever starts or calls a Prefect
API). Voyages go out in batches dealt longest-first so batches take similar time; a batch whose
worker is lost more often than dask retries becomes `failed` rows, never lost voyages.
"""

from __future__ import annotations

import contextlib
import logging
import math
from collections.abc import Callable, Iterator

LOG = logging.getLogger("jitroute.fleet")


def batches(jobs: list, per_batch: int, length_nm: Callable) -> list[list]:
    """Deal the jobs, longest first, round-robin into batches of about `per_batch` so batches take similar time."""
    ordered = sorted(jobs, key=lambda j: -length_nm(j))
    n = max(1, math.ceil(len(jobs) / max(1, per_batch)))
    return [ordered[k::n] for k in range(n) if ordered[k::n]]


MAX_VOYAGES_PER_BATCH = 16  # a batch's results (rows, and with exports ~0.5 MB of files a voyage) wait in its worker


def voyages_per_batch(n_jobs: int, n_slots: int, setting: int | None) -> int:
    """Explicit setting, else about three batches per worker thread (a batch is one dask task), at most
    MAX_VOYAGES_PER_BATCH voyages each: a worker holds a whole batch's results until they are collected, which for
    a large fleet on a small cluster was tens of MB of export files per worker."""
    if setting:
        return max(1, int(setting))
    return max(1, min(MAX_VOYAGES_PER_BATCH, math.ceil(n_jobs / (3 * max(1, n_slots)))))


def dashboard_of(client, address: str | None) -> str:
    """The dashboard link, or says there is none (an external scheduler started without one, e.g. no bokeh)."""
    if address is None:
        return client.dashboard_link
    services = (client.scheduler_info() or {}).get("services", {})
    return client.dashboard_link if "dashboard" in services else "none (the scheduler at this address serves no dashboard)"


@contextlib.contextmanager
def dask_client(address: str | None, n_workers: int,
                on_error: Callable[[BaseException], None] | None = None) -> Iterator[object]:
    """A client of the scheduler at `address`, or of a local cluster of `n_workers` single-threaded processes
    (closed again on exit, workers included). The dashboard is on a free loopback port and logged.

    `on_error(exc)` runs when the body raises (a SIGTERM's SystemExit included), before the cluster is closed: closing
    takes seconds on a busy machine, which a SIGTERM's grace period (cli/signals.py) may not outlast, so what must
    be recorded about the failure goes first."""
    import dask
    from distributed import Client, LocalCluster

    # no GIL monitor, no task profiler (flows/jobs/route_worker.stop_task_profiler says why) in the workers
    quiet = {"distributed.admin.system-monitor.gil.enabled": False, "distributed.worker.profile.enabled": False}
    for name in ("distributed", "distributed.nanny", "distributed.worker", "distributed.scheduler",
                 "distributed.core", "distributed.process", "distributed.http.proxy"):
        logging.getLogger(name).setLevel(logging.ERROR)  # progress is reported per voyage instead
    with dask.config.set(quiet):
        if address:
            client = Client(address, timeout="30s")
            cluster = None
        else:
            cluster = LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True,
                                   dashboard_address="127.0.0.1:0", silence_logs=logging.ERROR)
            client = Client(cluster)
        try:
            LOG.info("dask: %s, dashboard %s", address or f"local cluster of {n_workers} workers", dashboard_of(client, address))
            yield client
        except BaseException as exc:
            if on_error is not None:
                on_error(exc)
            raise
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
                _stop_resource_tracker()


def _stop_resource_tracker() -> None:
    """Stop multiprocessing's resource tracker, which the local cluster's worker processes started: it holds nothing
    once they are gone, and left running it outlives the command by a moment (a process left behind in its group).
    Started again if anything needs it later. Left alone while any worker process still runs: the tracker ends only
    once every holder of its pipe has, and stopping it waits for that."""
    import multiprocessing
    from multiprocessing import resource_tracker

    stop = getattr(resource_tracker._resource_tracker, "_stop", None)  # CPython's own; absent elsewhere
    if stop is not None and not multiprocessing.active_children():
        stop()


def worker_slots(client) -> int:
    """Worker threads of the live cluster (at least 1)."""
    try:
        return max(1, sum(w.get("nthreads", 1) for w in client.scheduler_info()["workers"].values()))
    except Exception:
        return 1


def map_batches(client, fn: Callable, batches_: list[list], *args, on_done: Callable[[list, list | None, BaseException | None], None],
                on_group_done: Callable[[], None] | None = None) -> None:
    """Run `fn(batch, *args)` for every batch on the cluster; `on_done(batch, results, error)` as each finishes, and
    `on_group_done()` after each group of batches found finished together (one store of their rows, however many)."""
    from distributed import as_completed

    futures = {client.submit(fn, b, *args, pure=False): b for b in batches_}
    for group in as_completed(list(futures)).batches():
        for fut in group:
            batch = futures[fut]
            try:
                results = fut.result()
            except Exception as exc:  # lost worker (KilledWorker), unpicklable result, …: the batch's voyages fail
                on_done(batch, None, exc)
            else:
                on_done(batch, results, None)
            finally:
                fut.release()
        if on_group_done is not None:
            on_group_done()


def result_or(future, on_error: Callable[[BaseException], object]):
    """The future's result, or `on_error(exception)` when its task failed or its worker was lost."""
    try:
        return future.result()
    except Exception as exc:  # lost worker (KilledWorker), an error in the task, …
        return on_error(exc)
    finally:
        future.release()
