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
from .outputs import ATTRIBUTES, FORMATS

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
InputFormat = Annotated[Optional[str], typer.Option("--input-format", metavar="FORMAT", help="Mesh format when reading standard input or a pipe (ply, obj, stl, off, glb).")]
Seed = Annotated[int, typer.Option("--seed", metavar="S", help="Random seed: same input, options and seed give the same bytes.")]


@app.command(no_args_is_help=True)
def sample(
    mesh: MeshArg,
    count: Annotated[Optional[int], typer.Option("-n", "--count", metavar="N", help="Number of points [default: 10000].")] = None,
    density: Annotated[Optional[float], typer.Option("--density", metavar="D", help="Points per unit of surface area, instead of -n.")] = None,
    output: Annotated[Optional[str], typer.Option("-o", "--output", metavar="PATH", help="Output file; '-' or absent: standard output.")] = None,
    fmt: Annotated[Optional[str], typer.Option("-f", "--format", metavar="FORMAT", help=f"{'|'.join(FORMATS)} [default: from the suffix of -o; CSV on standard output].")] = None,
    ascii: Annotated[bool, typer.Option("--ascii", help="ASCII PLY instead of binary little-endian.")] = False,
    seed: Seed = 0,
    attributes: Annotated[Optional[str], typer.Option("-a", "--attributes", metavar="LIST", help=f"Comma list of extra columns: {', '.join(ATTRIBUTES)}.")] = None,
    weight: Annotated[Optional[str], typer.Option("--weight", metavar="SOURCE", help="Density proportional to area times vertex-color:r|g|b|a or texture:r|g|b|a.")] = None,
    objects: Annotated[Optional[List[str]], typer.Option("--object", metavar="NAME", help="Sample only this scene object (repeatable).")] = None,
    poisson: Annotated[bool, typer.Option("--poisson", help="Thin to a Poisson-disk set of exactly N points with the largest spacing reached.")] = False,
    radius: Annotated[Optional[float], typer.Option("--radius", metavar="R", help="Thin to a maximal Poisson-disk set with this minimum distance.")] = None,
    exterior: Annotated[bool, typer.Option("--exterior", help="Only the exterior surface: what can be seen from outside the mesh (needs embreex).")] = False,
    method: Annotated[str, typer.Option("--method", metavar="METHOD", help="random (i.i.d., square-root warp) | stratified | sobol.")] = "random",
    precision: Annotated[str, typer.Option("--precision", metavar="PRECISION", help="auto|float32|float64; auto keeps float32 unless it moves points by more than 1e-6 of the bounding-box diagonal.")] = "auto",
    stats: Annotated[Optional[str], typer.Option("--stats", metavar="PATH", help="Write a JSON summary to this file ('-': standard error).")] = None,
    quiet: Annotated[bool, typer.Option("-q", "--quiet", help="No progress and no warnings.")] = False,
    chunk_size: Annotated[Optional[int], typer.Option("--chunk-size", metavar="K", help="Points generated per chunk (memory/speed knob; never changes the output).")] = None,
    input_format: InputFormat = None,
    stable: Annotated[bool, typer.Option("--stable", help="Placement keyed to the faces themselves: points stay put when the mesh is edited elsewhere, renumbered or re-exported.")] = False,
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
    process.lean_trimesh()
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
        input_format=input_format, warn=_warner(quiet), exterior=exterior, stable=stable,
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
