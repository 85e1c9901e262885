"""The ``scatter`` command line: a thin shell over :mod:`scatter_cli.api`."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import sys
import time
from typing import List, Optional

import typer

from .errors import OutputClosed, ScatterError, ScatterUsageError

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
    context_settings={"help_option_names": ["-h", "--help"]},
    help="Spread points uniformly over the surface of a mesh.\n\n"
    "  scatter sample bunny.obj -n 100000 -o bunny.ply\n\n"
    "  scatter sample scene.glb --poisson -n 5000 -a normal,color | head\n\n"
    "  scatter info mesh.ply",
)


def _warner(quiet):
    if quiet:
        return None
    return lambda message: print(f"warning: {message}", file=sys.stderr)


@app.command(no_args_is_help=True)
def sample(
    mesh: str = typer.Argument(..., metavar="MESH", help="Mesh file (PLY, OBJ, STL, OFF, GLB/GLTF, ...); '-' reads standard input."),
    count: Optional[int] = typer.Option(None, "-n", "--count", metavar="N", help="Number of points [default: 10000]."),
    density: Optional[float] = typer.Option(None, "--density", metavar="D", help="Points per unit of surface area, instead of -n."),
    output: Optional[str] = typer.Option(None, "-o", "--output", metavar="PATH", help="Output file; '-' or absent: standard output."),
    fmt: Optional[str] = typer.Option(None, "-f", "--format", metavar="FORMAT", help="ply|csv|xyz|npy [default: from the suffix of -o; CSV on standard output]."),
    ascii: bool = typer.Option(False, "--ascii", help="ASCII PLY instead of binary little-endian."),
    seed: int = typer.Option(0, "--seed", metavar="S", help="Random seed: same input, options and seed give the same bytes."),
    attributes: Optional[str] = typer.Option(None, "-a", "--attributes", metavar="LIST", help="Comma list of extra columns: normal, smooth-normal, face, bary, color, uv, object."),
    weight: Optional[str] = typer.Option(None, "--weight", metavar="SOURCE", help="Density proportional to area times vertex-color:r|g|b|a or texture:r|g|b|a."),
    objects: Optional[List[str]] = typer.Option(None, "--object", metavar="NAME", help="Sample only this scene object (repeatable)."),
    poisson: bool = typer.Option(False, "--poisson", help="Thin to a Poisson-disk set of exactly N points with the largest spacing reached."),
    radius: Optional[float] = typer.Option(None, "--radius", metavar="R", help="Thin to a maximal Poisson-disk set with this minimum distance."),
    stable: bool = typer.Option(False, "--stable", help="Placement keyed to the faces themselves: points stay put when the mesh is edited elsewhere, renumbered or re-exported."),
    method: str = typer.Option("random", "--method", metavar="METHOD", help="random (i.i.d., square-root warp) | stratified | sobol."),
    precision: str = typer.Option("auto", "--precision", metavar="PRECISION", help="auto|float32|float64; auto keeps float32 unless it moves points by more than 1e-6 of the bounding-box diagonal."),
    stats: Optional[str] = typer.Option(None, "--stats", metavar="PATH", help="Write a JSON summary to this file ('-': standard error)."),
    quiet: bool = typer.Option(False, "-q", "--quiet", help="No progress and no warnings."),
    chunk_size: Optional[int] = typer.Option(None, "--chunk-size", metavar="K", help="Points generated per chunk (memory/speed knob; never changes the output)."),
    input_format: Optional[str] = typer.Option(None, "--input-format", metavar="FORMAT", help="Mesh format when reading standard input or a pipe (ply, obj, stl, off, glb)."),
):
    """Sample points on the surface of MESH.

    Faces are chosen with probability proportional to their area and the point inside
    a face comes from the square-root warp, so the points are uniform over the surface.
    Points of the default random method form an exchangeable sequence: any prefix of
    the output is itself a uniform sample.

    Examples:

      scatter sample bunny.obj -n 100000 -o bunny.ply

      scatter sample part.stl --density 50 -a normal -o part.csv

      cat mesh.ply | scatter sample - --input-format ply -n 1000 -f xyz
    """
    from . import api
    from .progress import with_progress
    from .writers import infer_format, write_samples

    started = time.perf_counter()
    out_format = infer_format(output, fmt)
    if ascii and out_format != "ply":
        raise ScatterUsageError("--ascii applies to PLY output only")
    run = api.prepare(
        mesh, count, density=density, seed=seed, method=method, attributes=attributes, poisson=poisson,
        radius=radius, weight=weight, objects=objects, precision=precision, chunk_size=chunk_size,
        input_format=input_format, warn=_warner(quiet), stable=stable,
    )
    t = time.perf_counter()
    show = not quiet and sys.stderr.isatty()
    write_samples(with_progress(run.chunks(), run.count, show), output, out_format, run.layout, run.count, ascii)
    run.info["timings"]["sample_and_write"] = time.perf_counter() - t
    run.info["timings"]["total"] = time.perf_counter() - started
    if stats and run.kept is not None:
        run.info.update(run.spacing())
    if stats:
        _write_stats(run.info, stats)


def _write_stats(info, path):
    text = json.dumps(info, indent=2, default=float) + "\n"
    if path == "-":
        sys.stderr.write(text)
        return
    from .writers import open_output

    with open_output(path) as stream:
        stream.write(text.encode())


@app.command()
def info(
    mesh: str = typer.Argument(..., metavar="MESH", help="Mesh file; '-' reads standard input."),
    as_json: bool = typer.Option(False, "--json", help="Machine-readable JSON."),
    input_format: Optional[str] = typer.Option(None, "--input-format", metavar="FORMAT", help="Mesh format when reading standard input or a pipe."),
):
    """Faces, vertices, area, bounding box, degenerate faces, attributes and objects of MESH."""
    from .info import describe, format_text

    report = describe(mesh, input_format=input_format)
    print(json.dumps(report, indent=2) if as_json else format_text(report))


@app.command()
def check(
    mesh: str = typer.Argument(..., metavar="MESH", help="Mesh file."),
    count: int = typer.Option(100000, "-n", "--count", metavar="N", help="Points per sampler."),
    seed: int = typer.Option(0, "--seed", metavar="S", help="Random seed."),
    poisson: bool = typer.Option(False, "--poisson", help="Compare Poisson-disk sets of exactly N points."),
    radius: Optional[float] = typer.Option(None, "--radius", metavar="R", help="Compare Poisson-disk sets of minimum distance R."),
):
    """Compare this tool's samples of MESH with pymeshlab's against the exact distribution.

    Exits 0 when scatter's points are consistent with the exact surface distribution
    (and so at least as good as pymeshlab's), 1 when not.
    """
    from .check import run_check

    raise typer.Exit(run_check(mesh, count=count, seed=seed, poisson=poisson, radius=radius))


@app.command()
def bench(
    meshes: Optional[List[str]] = typer.Argument(None, help="Mesh files [default: an icosphere, samples/skull.ply, the icosphere moved by 1e6]."),
    out: str = typer.Option("bench-out", "--out", help="Directory for bench.md, bench.json and bench.png."),
    quick: bool = typer.Option(False, "--quick", help="Counts 1e2..1e4, 3 seeds: a smoke run for CI (under a minute)."),
    counts: Optional[str] = typer.Option(None, "--counts", help="Comma list of point counts [default: 1e2..1e7 in half decades]."),
    repeats: Optional[int] = typer.Option(None, "--repeats", help="Seeds per count (errors: RMS; time: median) [default: 5, quick 3]."),
    seed: int = typer.Option(0, "--seed", help="First seed; the same seed gives the same errors."),
    no_plot: bool = typer.Option(False, "--no-plot", help="Skip the PNG (no matplotlib needed)."),
):
    """What accuracy costs in time: error of exact surface integrals against count and time.

    For each method (random, stratified, sobol), warp (sqrt, fold, lowdist, naive),
    arithmetic precision and installed peer (trimesh, pymeshlab), estimates the centroid,
    the central second moments and a smooth function's mean from the points, compares
    them with their exact values, fits the convergence slope and writes a Markdown
    table, JSON and a PNG plot to --out. Needs matplotlib for the plot
    (pip install 'scatter-cli[bench]').
    """
    from .bench import run_bench

    parsed = None
    if counts:
        try:
            parsed = [int(float(c)) for c in counts.split(",") if c.strip()]
        except ValueError:
            raise ScatterUsageError(f"--counts must be a comma list of integers, not {counts!r}") from None
        if not parsed or min(parsed) < 2:
            raise ScatterUsageError("--counts must be integers >= 2")
    if repeats is not None and repeats < 1:
        raise ScatterUsageError(f"--repeats must be a positive integer, not {repeats}")
    report = run_bench(meshes or None, out=out, quick=quick, counts=parsed, repeats=repeats, seed=seed,
                       want_plot=not no_plot)
    print(report["markdown"])


@app.callback()
def _root(debug: bool = typer.Option(False, "--debug", help="Show tracebacks on errors.")):
    pass


class _Terminated(BaseException):
    pass


class _Interrupted(BaseException):
    """SIGINT, raised instead of KeyboardInterrupt: typer turns that into a silent Exit(130)."""


def _on_sigterm(signum, frame):
    raise _Terminated()


def _on_sigint(signum, frame):
    raise _Interrupted()


def _click_error_types():
    mro = typer.BadParameter.__mro__
    usage = next(c for c in mro if c.__name__ == "UsageError")
    base = next(c for c in mro if c.__name__ == "ClickException")
    return usage, base


def _import_trimesh_lean():
    """Import trimesh with SciPy hidden: trimesh imports SciPy eagerly when it is installed
    (0.4 s or more on every call) only for features that loading and sampling never use.
    Only the command line does this; the Python API leaves the user's trimesh alone.
    """
    if "trimesh" in sys.modules or "scipy" in sys.modules:
        return
    sys.modules["scipy"] = None  # makes `import scipy` raise ImportError
    try:
        import trimesh  # noqa: F401
    except Exception:
        pass  # a broken trimesh is reported where the mesh is loaded
    finally:
        del sys.modules["scipy"]


def main(argv=None):
    argv = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in argv
    if argv and argv[0] in ("sample", "info"):
        from . import surface

        surface.import_trimesh = _import_trimesh_lean  # when a mesh needs it, not before
    signal.signal(signal.SIGTERM, _on_sigterm)
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:  # not when started ignoring it (`cmd &`)
        signal.signal(signal.SIGINT, _on_sigint)
    usage_error, click_error = _click_error_types()
    command = typer.main.get_command(app)
    try:
        code = command.main(args=argv, prog_name="scatter", standalone_mode=False)
        code = code if isinstance(code, int) else 0
    except usage_error as exc:
        hint = f" (see '{exc.ctx.command_path} --help')" if getattr(exc, "ctx", None) else ""
        code = _fail(exc.format_message() + hint, 2)
    except ScatterError as exc:
        code = _fail(str(exc), exc.exit_code)
    except click_error as exc:
        code = _fail(exc.format_message(), exc.exit_code)
    except (BrokenPipeError, OutputClosed):
        # The reader went away (`| head`): stop quietly, as Unix tools do.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        code = 141
    except (KeyboardInterrupt, _Interrupted):
        code = _fail("interrupted", 130)
    except _Terminated:
        code = _fail("terminated", 143)
    except MemoryError:
        code = _fail("out of memory (try a smaller count or --chunk-size)", 1)
    except Exception as exc:
        if debug:
            raise
        code = _fail(f"internal error: {type(exc).__name__}: {exc} (run with --debug for a traceback)", 1)
    sys.exit(code)


def run():
    """The ``scatter`` command: :func:`main`, then exit without tearing the interpreter down.

    Freeing every module and array at exit takes about 25 ms after a large job, for
    nothing: the output is complete and closed by then, so only the standard streams
    need flushing.
    """
    try:
        main()
        code = 0
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    try:
        sys.stdout.flush()
    except (BrokenPipeError, ValueError):
        code = code or 141
    with contextlib.suppress(OSError, ValueError):
        sys.stderr.flush()
    os._exit(code)


def _fail(message, code):
    print(f"error: {message}", file=sys.stderr)
    return code
