"""The ``scatter`` command line: a thin typer shell over :mod:`scatter_cli.api`.

How the process runs (signals, exit codes, standard output) is :mod:`scatter_cli.process`.
"""

from __future__ import annotations

import json
import sys
import time
from typing import Annotated, List, Optional

import typer

from . import process
from .errors import ScatterUsageError
from .inputs import INPUT_FORMATS
from .outputs import ASCII_FORMATS, ATTRIBUTES, FORMATS

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


MeshArg = Annotated[str, typer.Argument(metavar="MESH", help="Mesh file (PLY, OBJ, STL, OFF, GLB/GLTF, ...); '-' reads standard input.")]
InputFormat = Annotated[Optional[str], typer.Option("--input-format", metavar="FORMAT", help=f"Mesh format when reading standard input or a pipe ({', '.join(INPUT_FORMATS)}).")]
Seed = Annotated[int, typer.Option("--seed", metavar="S", help="Random seed: same input, options and seed give the same bytes.")]
Exterior = Annotated[bool, typer.Option("--exterior", help="Only the exterior surface: what can be seen from outside the mesh (needs embreex).")]
Stable = Annotated[bool, typer.Option("--stable", help="Placement keyed to the faces themselves: points stay put when the mesh is edited elsewhere, renumbered or re-exported.")]
Shard = Annotated[Optional[str], typer.Option("--shard", metavar="K/M", help="Write only shard K (0-based) of M of the run's points; join shards with 'scatter merge'.")]


@app.command(no_args_is_help=True)
def sample(
    mesh: MeshArg,
    count: Annotated[Optional[int], typer.Option("-n", "--count", metavar="N", help="Number of points [default: 10000].")] = None,
    density: Annotated[Optional[float], typer.Option("--density", metavar="D", help="Points per unit of surface area, instead of -n.")] = None,
    output: Annotated[Optional[str], typer.Option("-o", "--output", metavar="PATH", help="Output file; '-' or absent: standard output.")] = None,
    fmt: Annotated[Optional[str], typer.Option("-f", "--format", metavar="FORMAT", help=f"{'|'.join(FORMATS)} [default: from the suffix of -o; CSV on standard output].")] = None,
    ascii: Annotated[bool, typer.Option("--ascii", help="ASCII PLY or PCD instead of binary.")] = False,
    seed: Seed = 0,
    attributes: Annotated[Optional[str], typer.Option("-a", "--attributes", metavar="LIST", help=f"Comma list of extra columns: {', '.join(ATTRIBUTES)}.")] = None,
    weight: Annotated[Optional[str], typer.Option("--weight", metavar="SOURCE", help="Density proportional to area times vertex-color:r|g|b|a or texture:r|g|b|a.")] = None,
    objects: Annotated[Optional[List[str]], typer.Option("--object", metavar="NAME", help="Sample only this scene object (repeatable); for a USD stage, a prim path: the meshes at or below it.")] = None,
    poisson: Annotated[bool, typer.Option("--poisson", help="Thin to a Poisson-disk set of exactly N points with the largest spacing reached.")] = False,
    radius: Annotated[Optional[float], typer.Option("--radius", metavar="R", help="Thin to a maximal Poisson-disk set with this minimum distance.")] = None,
    exterior: Exterior = False,
    method: Annotated[str, typer.Option("--method", metavar="METHOD", help="random (i.i.d., square-root warp) | stratified | sobol.")] = "random",
    precision: Annotated[str, typer.Option("--precision", metavar="PRECISION", help="auto|float32|float64; auto keeps float32 unless it moves points by more than 1e-6 of the bounding-box diagonal.")] = "auto",
    stats: Annotated[Optional[str], typer.Option("--stats", metavar="PATH", help="Write a JSON summary to this file ('-': standard error).")] = None,
    quiet: Annotated[bool, typer.Option("-q", "--quiet", help="No progress and no warnings.")] = False,
    chunk_size: Annotated[Optional[int], typer.Option("--chunk-size", metavar="K", help="Points generated per chunk (memory/speed knob; never changes the output).")] = None,
    input_format: InputFormat = None,
    stable: Stable = False,
    shard: Shard = None,
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

      scatter sample terrain.ply -n 1000000000 --shard 3/8 -o part-3.ply
    """
    process.lean_trimesh()
    from . import api
    from .progress import with_progress
    from .writers import infer_format, run_precision, write_samples

    started = time.perf_counter()
    out_format = infer_format(output, fmt)
    if ascii and out_format not in ASCII_FORMATS:
        raise ScatterUsageError(f"--ascii applies to {' and '.join(f.upper() for f in ASCII_FORMATS)} output only")
    run = api.prepare(
        mesh, count, density=density, seed=seed, method=method, attributes=attributes, poisson=poisson,
        radius=radius, weight=weight, objects=objects, precision=run_precision(out_format, precision),
        chunk_size=chunk_size, input_format=input_format, warn=_warner(quiet), exterior=exterior, stable=stable,
        shard=shard,
    )
    t = time.perf_counter()
    show = not quiet and sys.stderr.isatty()
    report = write_samples(with_progress(run.chunks(), run.size, show), output, out_format, run.layout, run.size,
                           ascii, **api.output_options(run, out_format))
    if report:
        run.info["output"] = report
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
    mesh: Annotated[str, typer.Argument(metavar="MESH", help="Mesh file; '-' reads standard input.")],
    as_json: Annotated[bool, typer.Option("--json", help="Machine-readable JSON.")] = False,
    input_format: InputFormat = None,
    exterior: Annotated[bool, typer.Option("--exterior", help="Also the exterior area (estimate and standard error) and faces seen from outside (needs embreex).")] = False,
):
    """Faces, vertices, area, bounding box, degenerate faces, attributes and objects of MESH."""
    process.lean_trimesh()
    from .info import describe, format_text

    report = describe(mesh, input_format=input_format, exterior=exterior)
    process.echo(json.dumps(report, indent=2) if as_json else format_text(report))


@app.command()
def check(
    mesh: Annotated[str, typer.Argument(metavar="MESH", help="Mesh file.")],
    count: Annotated[int, typer.Option("-n", "--count", metavar="N", help="Points per sampler.")] = 100000,
    seed: Annotated[int, typer.Option("--seed", metavar="S", help="Random seed.")] = 0,
    poisson: Annotated[bool, typer.Option("--poisson", help="Compare Poisson-disk sets of exactly N points.")] = False,
    radius: Annotated[Optional[float], typer.Option("--radius", metavar="R", help="Compare Poisson-disk sets of minimum distance R.")] = None,
):
    """Compare this tool's samples of MESH with pymeshlab's against the exact distribution.

    Exits 0 when scatter's points are consistent with the exact surface distribution
    (and so at least as good as pymeshlab's), 1 when not.
    """
    from .check import run_check

    raise typer.Exit(run_check(mesh, count=count, seed=seed, poisson=poisson, radius=radius, out=process.echo))


@app.command()
def bench(
    meshes: Annotated[Optional[List[str]], typer.Argument(metavar="[MESH]...", help="Mesh files [default: an icosphere, samples/skull.ply, the icosphere moved by 1e6].")] = None,
    out: Annotated[str, typer.Option("--out", metavar="DIR", help="Directory for bench.md, bench.json and bench.png.")] = "bench-out",
    quick: Annotated[bool, typer.Option("--quick", help="Counts 1e2..1e4, 3 seeds: a smoke run for CI (under a minute).")] = False,
    counts: Annotated[Optional[str], typer.Option("--counts", metavar="LIST", help="Comma list of point counts [default: 1e2..1e7 in half decades].")] = None,
    repeats: Annotated[Optional[int], typer.Option("--repeats", metavar="K", help="Seeds per count (errors: RMS; time: median) [default: 5, quick 3].")] = None,
    seed: Annotated[int, typer.Option("--seed", metavar="S", help="First seed; the same seed gives the same errors.")] = 0,
    no_plot: Annotated[bool, typer.Option("--no-plot", help="Skip the PNG (no matplotlib needed).")] = False,
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
    process.echo(report["markdown"])


@app.command(no_args_is_help=True)
def batch(
    inputs: Annotated[Optional[List[str]], typer.Argument(metavar="INPUT...", help="Mesh files and folders (searched recursively for mesh suffixes).", show_default=False)] = None,
    output: Annotated[str, typer.Option("-o", "--output", metavar="TEMPLATE", help="Output path per mesh, with {stem} {name} {rel} {index}.")] = ...,
    from_list: Annotated[Optional[str], typer.Option("--from-list", metavar="FILE", help="Read mesh paths, one a line, from FILE ('-': standard input).")] = None,
    jobs: Annotated[Optional[int], typer.Option("-j", "--jobs", metavar="N", help="Worker processes [default: the CPUs available].")] = None,
    skip_existing: Annotated[bool, typer.Option("--skip-existing", help="Skip a mesh whose output exists (outputs are atomic: an existing one is complete).")] = False,
    timeout: Annotated[Optional[float], typer.Option("--timeout", metavar="S", help="Fail a mesh that takes more than S seconds.")] = None,
    max_memory: Annotated[Optional[float], typer.Option("--max-memory", metavar="MB", help="Fail a mesh whose worker's resident memory passes MB.")] = None,
    report: Annotated[Optional[str], typer.Option("--report", metavar="PATH", help="JSON Lines report, one object per mesh, in input order.")] = None,
    engine: Annotated[str, typer.Option("--engine", metavar="ENGINE", help="local | dask.")] = "local",
    scheduler: Annotated[Optional[str], typer.Option("--scheduler", metavar="ADDRESS", help="Dask scheduler (tcp://host:8786) [default: DASK_SCHEDULER_ADDRESS].")] = None,
    count: Annotated[Optional[int], typer.Option("-n", "--count", metavar="N", help="Points per mesh [default: 10000].")] = None,
    density: Annotated[Optional[float], typer.Option("--density", metavar="D", help="Points per unit of surface area, instead of -n.")] = None,
    fmt: Annotated[Optional[str], typer.Option("-f", "--format", metavar="FORMAT", help=f"{'|'.join(FORMATS)} [default: from the suffix of the template].")] = None,
    ascii: Annotated[bool, typer.Option("--ascii", help="ASCII PLY instead of binary little-endian.")] = False,
    seed: Seed = 0,
    attributes: Annotated[Optional[str], typer.Option("-a", "--attributes", metavar="LIST", help=f"Comma list of extra columns: {', '.join(ATTRIBUTES)}.")] = None,
    weight: Annotated[Optional[str], typer.Option("--weight", metavar="SOURCE", help="Density proportional to area times vertex-color:r|g|b|a or texture:r|g|b|a.")] = None,
    objects: Annotated[Optional[List[str]], typer.Option("--object", metavar="NAME", help="Sample only this scene object (repeatable).")] = None,
    poisson: Annotated[bool, typer.Option("--poisson", help="Thin to a Poisson-disk set of exactly N points.")] = False,
    radius: Annotated[Optional[float], typer.Option("--radius", metavar="R", help="Thin to a maximal Poisson-disk set with this minimum distance.")] = None,
    method: Annotated[str, typer.Option("--method", metavar="METHOD", help="random | stratified | sobol.")] = "random",
    precision: Annotated[str, typer.Option("--precision", metavar="PRECISION", help="auto|float32|float64.")] = "auto",
    chunk_size: Annotated[Optional[int], typer.Option("--chunk-size", metavar="K", help="Points generated per chunk (never changes the output).")] = None,
    exterior: Exterior = False,
    stable: Stable = False,
    shard: Shard = None,
    quiet: Annotated[bool, typer.Option("-q", "--quiet", help="No progress, warnings, error lines or summary (the exit status and report still tell).")] = False,
):
    """Sample many meshes: for each, what 'scatter sample MESH -o OUTPUT' writes.

    OUTPUT is TEMPLATE filled in per mesh. One bad mesh (an error, a crash, --timeout or
    --max-memory exceeded) fails alone; exit 1 when any failed.

    Examples:

      scatter batch models/ -o points/{rel}.ply -n 2048 -a normal -j 8

      find /data -name '*.glb' | scatter batch --from-list - -o out/{index:07d}.npy --skip-existing

      scatter batch /shared/meshes -o /shared/pts/{rel}.ply --engine dask --scheduler tcp://head:8786
    """
    process.lean_trimesh()
    from .batch import run_batch

    options = dict(count=count, density=density, seed=seed, method=method, attributes=attributes, poisson=poisson,
                   radius=radius, weight=weight, objects=objects, precision=precision, chunk_size=chunk_size,
                   exterior=exterior or None, stable=stable or None, shard=shard)
    options = {k: v for k, v in options.items() if v is not None}
    result = run_batch(inputs or [], output, from_list=from_list, jobs=jobs, skip_existing=skip_existing,
                       timeout=timeout, max_memory=max_memory, report=report, engine=engine, scheduler=scheduler,
                       fmt=fmt, ascii=ascii, options=options, quiet=quiet, progress=sys.stderr.isatty())
    if result["failed"]:
        raise typer.Exit(1)


@app.command(no_args_is_help=True)
def merge(
    parts: Annotated[List[str], typer.Argument(metavar="PART...", help="Point files of one format and column layout, in order.")],
    output: Annotated[str, typer.Option("-o", "--output", metavar="OUTPUT", help="The joined file ('-': standard output).")],
    fmt: Annotated[Optional[str], typer.Option("-f", "--format", metavar="FORMAT", help="Format of the parts and output [default: from the suffixes].")] = None,
):
    """Join point files (such as the shards of one run) into one, in the order given.

    The shards of a run (scatter sample --shard K/M), merged in order, are that run's
    output byte for byte. Parts of different formats or columns are an error naming the
    first one that differs.

      scatter merge part-0.ply part-1.ply part-2.ply -o whole.ply
    """
    from .merge import merge as join

    join(parts, output, fmt)


def _print_version(value: bool):
    if value:
        from . import version

        process.echo(f"scatter {version()}")
        raise typer.Exit()


@app.callback()
def _root(
    ctx: typer.Context,
    debug: Annotated[bool, typer.Option("--debug", help="Show tracebacks on errors.")] = False,
    version: Annotated[bool, typer.Option("--version", is_eager=True, callback=_print_version, help="Print the version and exit.")] = False,
):
    ctx.ensure_object(process.Options).debug = debug


def main(argv=None) -> int:
    """Run ``scatter`` on ``argv`` (default: the process's arguments); returns the exit code."""
    argv = list(sys.argv[1:] if argv is None else argv)
    return process.run_command(typer.main.get_command(app), argv)


def run():
    """The ``scatter`` console script: :func:`main`, then exit at once."""
    process.exit_now(main())
