"""The Dask engine of ``scatter batch``: one task per mesh on a ``dask.distributed`` cluster.

A task is a pure function of (input path, output path, format, options): it samples the
mesh to the output on the worker, atomically, and returns the report record, so Dask
running it again after losing a worker writes the same bytes. Each Dask worker thread
keeps a :class:`scatter_cli.worker.Lane`, a long-lived child process, so a task that
crashes, runs past ``--timeout`` or past ``--max-memory`` fails alone (a record with
status ``failed``, which Dask does not retry) and the Dask worker lives on. Dask itself
reruns the tasks of a worker that was lost, up to its ``allowed-failures``; past that the
mesh is reported failed.

Dask is imported here only: the optional extra ``dask``.
"""

from __future__ import annotations

import os
import threading
import uuid

from .errors import ScatterError, ScatterUsageError

_local = threading.local()
WINDOW_PER_THREAD = 4  # tasks queued per worker thread: enough to keep them busy, not millions


def _import_distributed():
    try:
        import distributed
    except ImportError:
        raise ScatterError("the Dask engine needs dask.distributed: pip install 'scatter-cli[dask]'") from None
    return distributed


def connect(scheduler=None):
    """A Client for ``scheduler`` (else DASK_SCHEDULER_ADDRESS)."""
    distributed = _import_distributed()
    address = scheduler or os.environ.get("DASK_SCHEDULER_ADDRESS")
    if not address:
        raise ScatterUsageError("--engine dask needs --scheduler ADDRESS (or DASK_SCHEDULER_ADDRESS)")
    try:
        return distributed.Client(address, timeout=30, set_as_default=False)
    except (OSError, TimeoutError) as exc:
        raise ScatterError(f"cannot reach the Dask scheduler at {address}: {exc}") from None


def run_dask(jobs_iter, setup, fmt, *, client=None, scheduler=None, timeout=None, max_memory=None,
             skip_existing=False, done):
    """Run the jobs ``(index, input, output)`` as tasks; ``done(index, record)`` as each ends."""
    from .worker import name_the_file, record
    from .writers import infer_format

    distributed = _import_distributed()
    own = client is None
    if own:
        client = connect(scheduler)
    batch_id = uuid.uuid4().hex[:8]
    futures = {}
    try:
        window = WINDOW_PER_THREAD * max(1, sum(client.nthreads().values()))
        pending = distributed.as_completed(loop=client.loop)

        def submit():
            job = next(jobs_iter, None)
            if job is None:
                return False
            index, input, output = job
            future = client.submit(sample_task, input, output, infer_format(output, fmt), setup, timeout,
                                   max_memory, skip_existing, key=f"scatter-{batch_id}-{index}", pure=False)
            futures[future] = job
            pending.add(future)
            return True

        for _ in range(window):
            if not submit():
                break
        for future in pending:
            index, input, output = futures.pop(future)
            try:
                rec = future.result()
            except distributed.KilledWorker:  # the task took down every worker it ran on
                rec = record(input, output, "failed", name_the_file("every Dask worker that sampled it was lost", input))
            except Exception as exc:  # the task could not run there (scatter_cli missing on a worker?)
                rec = record(input, output, "failed", name_the_file(f"the Dask task failed: {type(exc).__name__}: {exc}", input))
            done(index, rec)
            submit()
    except BaseException:
        client.cancel(list(futures))
        raise
    finally:
        if own:
            client.close()


def sample_task(input, output, fmt, setup, timeout, max_memory, skip_existing):
    """The report record of one mesh, sampled on this Dask worker (see :mod:`scatter_cli.worker`)."""
    from .worker import Lane

    lane = getattr(_local, "lane", None)
    key = (repr(setup), timeout, max_memory, skip_existing)
    if lane is None or lane.key != key:
        if lane is not None:
            lane.close()
        lane = Lane(setup, None, timeout, max_memory, skip_existing)
        lane.key = key
        _local.lane = lane
    return lane.process(input, output, fmt)
