"""The Dask engine of ``scatter batch``: tasks of a few meshes on a ``dask.distributed`` cluster.

A task is a pure function of its meshes' (input path, output path, format, skip) and the
options: it samples each mesh to its output on the worker, atomically, and returns their
report records, so Dask running it again after losing a worker writes the same bytes.
Each Dask worker thread keeps a :class:`scatter_cli.engines.worker.Lane`, a long-lived child
process, so a mesh that runs past ``--timeout`` or past ``--max-memory`` fails alone (a
record with status ``failed``, which Dask does not retry) and the Dask worker lives on.
Dask itself reruns the tasks of a worker that was lost, up to its ``allowed-failures``,
and a task whose child process was lost (killed from outside, or crashed) as many times;
past that the task's meshes are run again one a task, and the one that still loses its
workers is reported failed. Once every task is done, the command removes the temporary
files beside the batch's outputs (what lost workers or earlier runs left): the workers'
lanes live from batch to batch, so a listing of theirs would miss what came later.

Dask is imported here only: the optional extra ``dask``.
"""

from __future__ import annotations

import array
import itertools
import os
import threading
import time
import uuid

from ..errors import ScatterError, ScatterUsageError

_local = threading.local()
WINDOW_PER_THREAD = 16  # tasks in flight per worker thread: enough to keep them busy, not millions
FIRST_PER_THREAD = 2  # tasks of one mesh per worker thread first, until a record tells the time per mesh
GATHER_EVERY = 0.2  # seconds a finished task's records may wait to be fetched with others
TASK_SECONDS = 0.2  # the sampling time a task aims at (see GroupSize)
MAX_GROUP = 16  # meshes a task samples at most


def _import_distributed():
    try:
        import distributed
    except ImportError:
        raise ScatterError("the Dask engine needs dask.distributed: pip install 'dask[distributed]'") from None
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

    A task samples a group of consecutive meshes (:class:`GroupSize`). At most
    ``WINDOW_PER_THREAD`` tasks per worker thread are in flight, submitted in blocks (one
    message to the scheduler per block, not one per task). The records of finished tasks
    are fetched together (one request for many), at most ``GATHER_EVERY`` seconds late or
    one completion late, whichever is later (at once until the time per mesh is known).
    A group that gives no records (its workers were lost past Dask's allowed-failures) is
    run again one mesh a task, so only a mesh that kills its workers fails.

    Every path is made absolute here, against this process's folder, before its task
    exists (a Dask worker runs in a folder of its own); the records and their messages
    give the paths as ``jobs_iter`` spelled them. With ``skip_existing`` whether each
    output exists is decided here, once, before its task exists: a task Dask runs again
    after losing a worker that had written the output writes it again (the same bytes)
    and reports it written, not skipped.
    """
    distributed = _import_distributed()
    own = client is None
    if own:
        client = connect(scheduler)
    batch_id = uuid.uuid4().hex[:8]
    tasks = {}  # future -> its jobs [(index, input, output, fmt, skip)], until its records are in
    given = {}  # index -> (input, output) as given, for the jobs in flight
    size = GroupSize()
    outputs = BatchOutputs()
    try:
        threads = max(1, sum(client.nthreads().values()))
        window = WINDOW_PER_THREAD * threads
        retries = allowed_failures(client)
        pending = distributed.as_completed(loop=client.loop)
        jobs = _task_jobs(jobs_iter, fmt, skip_existing, given, outputs)

        def finish(job, rec):
            done(job[0], as_given(rec, *given.pop(job[0])))

        def submit(groups, keys):
            if groups:
                futures = client.map(sample_group, groups, key=keys, pure=False, retries=retries, setup=setup,
                                     timeout=timeout, max_memory=max_memory)
                tasks.update(zip(futures, groups))
                pending.update(futures)

        def refill(room=window):
            groups = [g for g in (list(itertools.islice(jobs, size.size)) for _ in range(room - pending.count())) if g]
            submit(groups, [f"scatter-{batch_id}-{g[0][0]}" for g in groups])

        refill(FIRST_PER_THREAD * threads)
        ready, since = [], 0.0
        for finished in pending.batches():
            if not ready:
                since = time.monotonic()
            ready.extend(finished)
            if (pending.is_empty() or not size.meshes or len(ready) >= window // 2
                    or time.monotonic() - since >= GATHER_EVERY):
                alone = []
                for future, got in zip(ready, _records(client, ready, distributed)):
                    group = tasks.pop(future)
                    if isinstance(got, list):
                        size.learn(got)
                        for job, rec in zip(group, got):
                            finish(job, rec)
                    elif len(group) > 1:
                        alone.extend([job] for job in group)
                    else:
                        finish(group[0], _lost(got, group[0][1], group[0][2], retries, distributed))
                submit(alone, [f"scatter-{batch_id}-{g[0][0]}-alone" for g in alone])
                ready = []
            if pending.count() <= window // 2:
                refill()
        outputs.clear_temps()  # (every task is done: none of this batch's is still writing)
    except BaseException:
        client.cancel(list(tasks))
        raise
    finally:
        if own:
            client.close()


def _task_jobs(jobs_iter, fmt, skip_existing, given, outputs):
    """The jobs as tasks take them: ``(index, input, output, format, skip)``, the paths
    absolute; ``given[index]`` keeps the paths as ``jobs_iter`` spelled them, ``outputs``
    (:class:`BatchOutputs`) each output."""
    from ..writers import infer_format

    for index, input, output in jobs_iter:
        given[index] = (input, output)
        target = os.path.abspath(output)
        outputs.add(target)
        yield index, os.path.abspath(input), target, infer_format(output, fmt), skip_existing and os.path.isfile(target)


def as_given(rec, input, output):
    """The record ``rec`` of a task (absolute paths) with the paths spelled as given, in
    its fields and its messages."""
    spelled = sorted({(rec["output"], output), (rec["input"], input)}, key=lambda pair: -len(pair[0]))

    def respell(text):
        for absolute, shown in spelled:
            text = text.replace(absolute, shown)
        return text

    rec = dict(rec, input=input, output=output)
    if rec["error"]:
        rec["error"] = respell(rec["error"])
    if rec.get("warnings"):
        rec["warnings"] = [respell(w) for w in rec["warnings"]]
    return rec


class BatchOutputs:
    """The outputs of a batch, one hash each, and their folders: where its end looks for
    the temporary files of lost workers."""

    def __init__(self):
        self.folders = set()
        self.hashes = array.array("q")

    def add(self, path):
        self.folders.add(os.path.dirname(path))
        self.hashes.append(hash(path))

    def __contains__(self, path):
        return hash(path) in self.hashes  # a scan: asked only of the temporary files found

    def clear_temps(self):
        from .worker import remove_temps_of

        remove_temps_of(self.folders, self.__contains__)


def allowed_failures(client) -> int:
    """The scheduler's ``allowed-failures``: how many times a task is run again after its
    worker was lost, and so after its child process was (this client's setting where the
    scheduler does not answer)."""
    import dask

    try:
        return int(client.run_on_scheduler(lambda dask_scheduler: dask_scheduler.allowed_failures))
    except Exception:  # a scheduler that runs no function sent to it
        return int(dask.config.get("distributed.scheduler.allowed-failures"))


class GroupSize:
    """How many meshes the next task samples: enough that a task takes about
    ``TASK_SECONDS`` (Dask's own cost per task is milliseconds of scheduler and worker
    time, more than a small mesh's sampling), at most ``MAX_GROUP``; one until records
    tell how long a mesh takes, so a collection of huge meshes is never grouped."""

    size = 1

    def __init__(self):
        self.meshes = 0
        self.seconds = 0.0

    def learn(self, records):
        self.meshes += len(records)
        self.seconds += sum(r["seconds"] for r in records)
        self.size = max(1, min(MAX_GROUP, int(TASK_SECONDS * self.meshes / max(self.seconds, 1e-9))))


def _records(client, futures, distributed):
    """The records of finished tasks, fetched in one request; for a task that gave none,
    its exception."""
    got = client.gather({f.key: f for f in futures}, errors="skip")
    return [got.get(f.key) or _exception(f, distributed) for f in futures]


def _exception(future, distributed):
    if future.status == "error":
        return future.exception()
    return distributed.CancelledError(future.key)


def _lost(exc, input, output, retries, distributed):
    """The failure record of a task that gave no record: its workers or its child
    processes were lost (the child's: ``retries`` + 1 times), or it could not run there."""
    from .worker import WorkerLost, name_the_file, record

    if isinstance(exc, distributed.KilledWorker):
        why = f"the Dask worker sampling it was lost {exc.allowed_failures + 1} times (Dask's allowed-failures)"
    elif isinstance(exc, WorkerLost):
        why = f"{exc}, {retries + 1} time{'s' if retries else ''} (Dask's allowed-failures)"
    else:
        why = f"the Dask task failed: {type(exc).__name__}: {exc}"
    return record(input, output, "failed", name_the_file(why, input))


def sample_group(jobs, *, setup, timeout, max_memory):
    """The report records of the meshes ``jobs`` [(index, input, output, format, skip)], sampled
    one after another on this Dask worker (see :mod:`scatter_cli.engines.worker`)."""
    from .worker import KeptTemps, Lane

    lane = getattr(_local, "lane", None)
    key = (repr(setup), timeout, max_memory)
    if lane is None or lane.key != key:
        if lane is not None:
            lane.close()
        lane = Lane(setup, None, timeout, max_memory, stale=KeptTemps(), crash_raises=True)
        lane.key = key
        _local.lane = lane
    records = []
    lane.run(jobs, lambda index, rec: records.append(rec))
    return records
