"""``scatter batch``: many meshes in one command, each written as ``scatter sample`` would.

The inputs are listed (and their outputs checked for collisions) before any work; then
an engine runs one job per mesh: the local engine in ``-j`` long-lived worker processes
(:mod:`scatter_cli.engines.worker`), the Dask engine as tasks on a cluster
(:mod:`scatter_cli.engines.dask_engine`). The report and the summary come from here, the same
for both.
"""

from __future__ import annotations

import array
import os
import re
import string
import sys
import time

from ..core.native import available_cpus
from ..errors import ScatterError, ScatterUsageError
from ..loading.formats import MESH_SUFFIXES
from ..run.options import SampleOptions

TEMPLATE_FIELDS = ("stem", "name", "rel", "index")
ENGINES = ("local", "dask")


class Inputs:
    """The meshes of a batch in input order: paths, held once, and the folder each was
    found under (for ``{rel}``). Folders are searched for files with ``suffixes``."""

    def __init__(self, suffixes=MESH_SUFFIXES):
        self.suffixes = suffixes
        self.paths = []
        self.roots = []  # folders given as INPUT
        self.root_of = array.array("i")  # per path: index into roots, -1 for a file given directly

    def add(self, item):
        """An INPUT: a folder (searched), or a file; a folder that does not exist is an error."""
        item = os.fspath(item)
        if os.path.isdir(item):
            self.add_folder(item)
        elif item.endswith(("/", os.sep)):
            raise ScatterError(f"{item}: no such folder")
        else:
            self.add_file(item)

    def add_file(self, path, root=-1):
        self.paths.append(path)
        self.root_of.append(root)

    def add_folder(self, folder):
        self.roots.append(folder)
        root = len(self.roots) - 1
        found = []
        for top, dirs, files in os.walk(folder):
            dirs.sort()
            found.extend(os.path.join(top, f) for f in files if os.path.splitext(f)[1].lower() in self.suffixes)
        found.sort(key=lambda p: _below(p, folder).split(os.sep))
        for p in found:
            self.add_file(p, root)

    def add_list(self, source):
        """One path a line from the file ``source`` (``-``: standard input), streamed."""
        stream = sys.stdin if source == "-" else _open_list(source)
        try:
            for line in stream:
                path = line.rstrip("\r\n")
                if path:
                    self.add_file(path)
        finally:
            if stream is not sys.stdin:
                stream.close()

    def __len__(self):
        return len(self.paths)

    def fields(self, i, wanted=TEMPLATE_FIELDS):
        """The template fields of mesh ``i``: those ``wanted`` (an output template's, see
        :attr:`Template.fields`; a batch fills one per mesh, twice)."""
        path = self.paths[i]
        out = {"index": i}
        if "name" in wanted or "stem" in wanted or ("rel" in wanted and self.root_of[i] < 0):
            out["name"] = name = os.path.basename(path)
            out["stem"] = os.path.splitext(name)[0]
        if "rel" in wanted:
            root = self.root_of[i]
            out["rel"] = out["stem"] if root < 0 else os.path.splitext(_below(path, self.roots[root]))[0]
        return out


def _below(path, folder):
    """``path`` relative to ``folder``, which ``os.walk(folder)`` found it under: as
    os.path.relpath gives it, by cutting the string (relpath makes both absolute first,
    a cost per mesh the batch's own thread would pay at tens of thousands of them)."""
    if path.startswith(folder):
        return path[len(folder):].lstrip(os.sep)
    return os.path.relpath(path, folder)


def _open_list(path):
    try:
        return open(path, encoding="utf-8", errors="surrogateescape")
    except OSError as exc:
        raise ScatterUsageError(f"{path}: cannot read the list of meshes: {exc.strerror or exc}") from None


def collect_inputs(inputs=(), from_list=None) -> Inputs:
    found = Inputs()
    for item in ([inputs] if isinstance(inputs, (str, os.PathLike)) else inputs or ()):
        found.add(item)
    if from_list is not None:
        found.add_list(os.fspath(from_list))
    if not len(found):
        given = ", ".join(map(str, [*([inputs] if isinstance(inputs, str) else inputs or ()), *([from_list] if from_list else [])]))
        raise ScatterUsageError(f"no mesh files to sample in: {given or 'nothing given'}")
    return found


class Template:
    """``-o TEMPLATE`` filled in per mesh; checked once against a sample of fields."""

    def __init__(self, text):
        self.text = os.fspath(text)
        try:
            self.text.format(stem="s", name="n", rel="r", index=0)
            # the fields it names (a field's own attributes or items after its name)
            self.fields = {re.split(r"[.\[]", name, maxsplit=1)[0] for _, name, _, _ in string.Formatter().parse(self.text)
                           if name}
        except (KeyError, IndexError) as exc:
            raise ScatterUsageError(f"unknown field {exc} in the output template '{self.text}' "
                                    f"(fields: {', '.join('{' + f + '}' for f in TEMPLATE_FIELDS)})") from None
        except ValueError as exc:
            raise ScatterUsageError(f"bad output template '{self.text}': {exc}") from None

    def output(self, found, i):
        """The output path of mesh ``i`` of ``found`` (:class:`Inputs`)."""
        return self.text.format(**found.fields(i, self.fields))


def plan_outputs(found: Inputs, template: Template, fmt=None):
    """Check every output before any work: a format known from its suffix (or ``fmt``), and
    no two meshes writing one path. Holds one hash per output, not the paths."""
    from ..writers import infer_format

    seen = {}
    suffixes = set()
    cwd = os.getcwd()  # (os.path.abspath asks for it at every call)
    for i in range(len(found)):
        out = template.output(found, i)
        suffix = os.path.splitext(out)[1].lower()
        if suffix not in suffixes:
            infer_format(out, fmt)
            suffixes.add(suffix)
        key = hash(os.path.normpath(os.path.join(cwd, out)))
        if key in seen:
            first = seen[key]
            if _same_output(template.output(found, first), out):
                raise ScatterUsageError(f"{found.paths[first]} and {found.paths[i]} would both write {out}: "
                                        "use {rel} or {index} in the output template")
        seen[key] = i


def _same_output(a, b):
    return os.path.normpath(os.path.abspath(a)) == os.path.normpath(os.path.abspath(b))


def _check_batch_options(jobs, timeout, max_memory, engine, scheduler):
    if jobs is not None and (not isinstance(jobs, int) or jobs < 1):
        raise ScatterUsageError(f"--jobs must be a positive integer, not {jobs!r}")
    if timeout is not None and not timeout > 0:
        raise ScatterUsageError(f"--timeout must be a positive number of seconds, not {timeout!r}")
    if max_memory is not None and not max_memory > 0:
        raise ScatterUsageError(f"--max-memory must be a positive number of MB, not {max_memory!r}")
    if engine not in ENGINES:
        raise ScatterUsageError(f"unknown engine '{engine}' (choose from: {', '.join(ENGINES)})")
    if scheduler is not None and engine != "dask":
        raise ScatterUsageError("--scheduler needs --engine dask (the local engine has no scheduler)")


def batch(inputs, output, *, jobs=None, skip_existing=False, timeout=None, max_memory=None, report=None,
          client=None, **sample_options) -> list:
    """Sample many meshes: for each, what ``sample(mesh)`` written to ``output`` gives.

    inputs: paths of meshes and of folders (searched recursively for mesh suffixes).
    output: the template, with fields ``{stem} {name} {rel} {index}``.
    client: a ``dask.distributed.Client``: run the meshes as tasks on its cluster.
    Returns the report records (one dict per mesh, in input order); ``report`` also
    writes them as JSON Lines. A mesh that fails is a record with status ``failed``.
    """
    fmt = sample_options.pop("format", None)
    ascii = sample_options.pop("ascii", False)
    crs = sample_options.pop("crs", None)
    return run_batch(inputs, output, jobs=jobs, skip_existing=skip_existing, timeout=timeout,
                     max_memory=max_memory, report=report, client=client, fmt=fmt, ascii=ascii, crs=crs,
                     options=SampleOptions(**sample_options), quiet=True, collect=True)["records"]


def run_batch(inputs, output, *, from_list=None, jobs=None, skip_existing=False, timeout=None, max_memory=None,
              report=None, engine="local", scheduler=None, client=None, fmt=None, ascii=False, crs=None, options=None,
              quiet=False, progress=False, collect=False):
    """The batch behind both the command and :func:`batch`; ``options``: the
    :class:`~scatter_cli.run.options.SampleOptions` of every mesh.

    Returns ``{"written", "skipped", "failed", "seconds", "records"}`` (records only
    with ``collect``). KeyboardInterrupt and other exceptions stop the workers, remove
    the outputs in progress and propagate.
    """
    from ..writers import check_output, infer_format

    started = time.monotonic()
    if client is not None:
        engine = "dask"
    _check_batch_options(jobs, timeout, max_memory, engine, scheduler)
    options = (options or SampleOptions()).check()
    if fmt is not None:
        fmt = infer_format(None, fmt)
        check_output(fmt, ascii, crs)
    template = Template(output)
    found = collect_inputs(inputs, from_list)
    plan_outputs(found, template, fmt)
    check_output(infer_format(template.output(found, 0), fmt), ascii, crs)
    setup = {"options": options.as_dict(), "ascii": ascii, "crs": crs, "quiet": quiet}
    if report is not None and os.fspath(report) != "-":
        report = os.path.abspath(report)
        from .worker import remove_temps

        remove_temps(report)  # what a killed run of this report left (outputs' are cleared per mesh)
    tally = Tally(len(found), report, collect, progress and not quiet, quiet)
    jobs_iter = ((i, found.paths[i], template.output(found, i)) for i in range(len(found)))
    try:
        if engine == "dask":
            from .dask_engine import run_dask

            run_dask(jobs_iter, setup, fmt, client=client, scheduler=scheduler, timeout=timeout,
                     max_memory=max_memory, skip_existing=skip_existing, done=tally.add)
        else:
            run_local(jobs_iter, setup, fmt, jobs=min(jobs or available_cpus(), len(found)), timeout=timeout,
                      max_memory=max_memory, skip_existing=skip_existing, done=tally.add)
    finally:
        tally.close()
    result = tally.summary(time.monotonic() - started)
    if not quiet:
        print(f"batch: {result['written']} written, {result['skipped']} skipped, {result['failed']} failed "
              f"in {result['seconds']:.1f} s", file=sys.stderr)
    return result


def run_local(jobs_iter, setup, fmt, *, jobs, timeout, max_memory, skip_existing, done):
    """``jobs`` lanes (threads, each driving one worker process) take meshes one at a time.

    The workers are forked from this process, after it has imported what they need, when
    it may fork (:func:`scatter_cli.engines.worker.can_fork`): none imports NumPy again.
    """
    import queue
    import threading

    from .worker import Lane, StaleTemps, WorkerProcess, can_fork, preload
    from ..writers import infer_format

    env = dict(os.environ)
    env.setdefault("SCATTER_THREADS", str(max(1, available_cpus() // jobs)))
    stale = StaleTemps()
    lock = threading.Lock()
    results = queue.Queue()
    fork = can_fork()
    if fork:
        preload()
    lanes = [Lane(setup, env, timeout, max_memory, skip_existing, stale,
                  WorkerProcess(setup, env, fork=True) if fork else None) for _ in range(jobs)]

    def take():
        while True:
            with lock:
                job = next(jobs_iter, None)
            if job is None:
                return
            index, input, output = job
            yield index, input, output, infer_format(output, fmt), None

    done_lock = threading.Lock()

    def finished(index, rec):  # in the lane's thread: no hop to the main thread per mesh
        with done_lock:
            done(index, rec)

    def work(lane):
        try:
            lane.run(take(), finished)
        except BaseException as exc:  # noqa: BLE001 (handed to the main thread)
            if not lane.stopped:
                results.put((None, exc))
        finally:
            lane.close()
            results.put((None, None))  # this lane is done

    threads = [threading.Thread(target=work, args=(lane,), daemon=True) for lane in lanes]
    for t in threads:
        t.start()
    try:
        running = len(threads)
        while running:  # the lanes' ends and failures (the main thread takes the signals)
            try:
                _, failure = results.get(timeout=1.0)
            except queue.Empty:
                continue
            if failure is None:
                running -= 1
            else:
                raise failure
    except BaseException:
        for lane in lanes:
            lane.stop()
        for t in threads:
            t.join(timeout=10)
        raise


class Tally:
    """Counts, the report in input order, the error lines and the progress line."""

    def __init__(self, total, report, collect, progress, quiet):
        self.total = total
        self.counts = {"written": 0, "skipped": 0, "failed": 0}
        self.pending = {}
        self.next = 0
        self.records = [] if collect else None
        self.progress = progress
        self.quiet = quiet
        self.started = self.last_drawn = time.monotonic()
        self.drawn = False
        self._report_cm = None
        self.stream = None
        if report is not None:
            from ..writers import open_output

            self._report_cm = open_output(report)
            self.stream = self._report_cm.__enter__()

    def add(self, index, rec):
        """The record ``rec`` of mesh ``index``: its warnings (a list the report does not
        keep, each naming the mesh) and its error are printed, the progress line erased first."""
        self.counts[rec["status"]] += 1
        warnings = rec.pop("warnings", None) or ()
        if not self.quiet:
            lines = [f"warning: {w}" for w in warnings]
            if rec["status"] == "failed":
                lines.append(f"error: {rec['error']}")
            if lines:
                self._clear_line()
                print("\n".join(lines), file=sys.stderr, flush=True)
        self.pending[index] = rec
        while self.next in self.pending:
            self._emit(self.pending.pop(self.next))
            self.next += 1
        self._draw()

    def _emit(self, rec):
        if self.records is not None:
            self.records.append(rec)
        if self.stream is not None:
            import json

            self.stream.write((json.dumps(rec) + "\n").encode())

    def close(self):
        """Write what is done (records after a gap too, still in input order) and commit the report."""
        for index in sorted(self.pending):
            self._emit(self.pending.pop(index))
        self._clear_line()
        if self._report_cm is not None:
            cm, self._report_cm = self._report_cm, None
            cm.__exit__(None, None, None)

    def summary(self, seconds):
        return dict(self.counts, seconds=seconds, records=self.records)

    def _draw(self):
        if not self.progress:
            return
        now = time.monotonic()
        if now - self.last_drawn < 0.2 and sum(self.counts.values()) < self.total:
            return
        self.last_drawn = now
        done = sum(self.counts.values())
        elapsed = max(now - self.started, 1e-9)
        rate = done / elapsed
        left = (self.total - done) / rate if rate else 0.0
        sys.stderr.write(f"\rbatch: {done:,}/{self.total:,} done, {self.counts['failed']:,} failed, "
                         f"{rate:.1f} meshes/s, {left:.0f} s left ")
        sys.stderr.flush()
        self.drawn = True

    def _clear_line(self):
        if self.drawn:
            sys.stderr.write("\r\033[K")
            sys.stderr.flush()
            self.drawn = False
