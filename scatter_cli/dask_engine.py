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

import itertools
import os
import threading
import time
import uuid

from .errors import ScatterError, ScatterUsageError

_local = threading.local()
WINDOW_PER_THREAD = 16  # tasks in flight per worker thread: enough to keep them busy, not millions
GATHER_EVERY = 0.2  # seconds a finished task's record may wait to be fetched with others


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
    """Run the jobs ``(index, input, output)`` as tasks; ``done(index, record)`` as each ends.

    At most ``WINDOW_PER_THREAD`` tasks per worker thread are in flight, submitted in
    blocks (one message to the scheduler per block, not one per mesh). The records of
    finished tasks are fetched together (one request for many), at most
    ``GATHER_EVERY`` seconds late or one completion late, whichever is later.
    """
    from .writers import infer_format

    distributed = _import_distributed()
    own = client is None
    if own:
        client = connect(scheduler)
    batch_id = uuid.uuid4().hex[:8]
    jobs = {}  # future -> (index, input, output), until its record is in
    try:
        window = WINDOW_PER_THREAD * max(1, sum(client.nthreads().values()))
        pending = distributed.as_completed(loop=client.loop)

        def refill():
            block = list(itertools.islice(jobs_iter, window - pending.count()))
            if block:
                futures = client.map(sample_task, [j[1] for j in block], [j[2] for j in block],
                                     [infer_format(j[2], fmt) for j in block],
                                     key=[f"scatter-{batch_id}-{j[0]}" for j in block], pure=False, setup=setup,
                                     timeout=timeout, max_memory=max_memory, skip_existing=skip_existing)
                jobs.update(zip(futures, block))
                pending.update(futures)

        refill()
        ready, since = [], 0.0
        for finished in pending.batches():
            if not ready:
                since = time.monotonic()
            ready.extend(finished)
            if pending.count() <= window // 2:
                refill()
            if pending.is_empty() or len(ready) >= window // 2 or time.monotonic() - since >= GATHER_EVERY:
                for future, rec in zip(ready, _records(client, ready, distributed)):
                    index, input, output = jobs.pop(future)
                    done(index, rec if isinstance(rec, dict) else _lost(rec, input, output, distributed))
                ready = []
    except BaseException:
        client.cancel(list(jobs))
        raise
    finally:
        if own:
            client.close()


def _records(client, futures, distributed):
    """The records of finished tasks, fetched in one request; for a task that gave none,
    its exception."""
    got = client.gather({f.key: f for f in futures}, errors="skip")
    return [got.get(f.key) or _exception(f, distributed) for f in futures]


def _exception(future, distributed):
    if future.status == "error":
        return future.exception()
    return distributed.CancelledError(future.key)


def _lost(exc, input, output, distributed):
    """The failure record of a task that gave no record: its workers were lost, or it
    could not run there."""
    from .worker import name_the_file, record

    if isinstance(exc, distributed.KilledWorker):
        why = f"the Dask worker sampling it was lost {exc.allowed_failures + 1} times (Dask's allowed-failures)"
    else:
        why = f"the Dask task failed: {type(exc).__name__}: {exc}"
    return record(input, output, "failed", name_the_file(why, input))


def sample_task(input, output, fmt, *, setup, timeout, max_memory, skip_existing):
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
