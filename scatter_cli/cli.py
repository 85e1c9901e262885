"""The ``scatter`` command line: a thin typer shell over :mod:`scatter_cli.api`.

How the process runs (signals, exit codes, standard output) is :mod:`scatter_cli.core.process`.
"""

import inspect
import json
import sys
import time
from typing import Annotated, List, Optional

import typer

from .core import process
from .errors import ScatterUsageError
from .loading.formats import INPUT_FORMATS
from .run.options import DEFAULT_COUNT, PADDING, SIGNS, SampleOptions, whole_number
from .run.fields import ATTRIBUTES
from .writers.formats import ASCII_FORMATS, FORMATS, MERGEABLE

app = typer.Typer(
    add_completion=True,  # --install-completion, --show-completion [bash|zsh|fish|powershell]
    invoke_without_command=True,  # `scatter` alone: the usage line and a hint (_root)
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
    context_settings={"help_option_names": ["-h", "--help"]},
    help="Spread points uniformly over the surface of a mesh.\n\n"
    "  scatter sample bunny.obj -n 100000 -o bunny.ply\n\n"
    "  scatter sample scene.glb --poisson -n 5000 -a normal,color | head\n\n"
    "  scatter info mesh.ply",
)


def lean_trimesh():
    """trimesh imported without SciPy when a mesh needs it (the command line only)."""
    from .loading.load import lean_trimesh

    lean_trimesh()


def _warner(quiet):
    if quiet:
        return None
    return lambda message: print(f"warning: {message}", file=sys.stderr)


MeshArg = Annotated[str, typer.Argument(metavar="MESH", help="Mesh file (PLY, OBJ, STL, OFF, GLB/GLTF, ...); '-' reads standard input.")]
InputFormat = Annotated[Optional[str], typer.Option("--input-format", metavar="FORMAT", help=f"Mesh format when reading standard input or a pipe ({', '.join(INPUT_FORMATS)}).")]


def _count(text):
    """A count as a user types it: 1000, 1e6, 2.5e3 (a whole number); 1.5 is refused."""
    if isinstance(text, int):
        return text
    try:
        return whole_number(text)
    except ValueError as exc:
        raise typer.BadParameter(f"{exc} (a count is a whole number, such as 1000 or 1e6)") from None


# The sample options, declared once: `sample`, `batch` and `preview` each take those it
# names (sample_options). Each is named as its SampleOptions field, with that field's
# default (D), or is an option of the output (fmt, ascii, crs).
D = SampleOptions()


def _declared(
    *,
    count: Annotated[Optional[int], typer.Option("-n", "--count", metavar="N", parser=_count, help=f"Number of points (per mesh) [default: {DEFAULT_COUNT}]; 1e6 is a count too.")] = D.count,
    density: Annotated[Optional[float], typer.Option("--density", metavar="D", help="Points per unit of surface area, instead of -n.")] = D.density,
    fmt: Annotated[Optional[str], typer.Option("-f", "--format", metavar="FORMAT", help=f"{'|'.join(FORMATS)} [default: from the suffix of the output; CSV on standard output].")] = None,
    ascii: Annotated[bool, typer.Option("--ascii", help=f"ASCII instead of binary ({' or '.join(f.upper() for f in ASCII_FORMATS)}).")] = False,
    seed: Annotated[int, typer.Option("--seed", metavar="S", help="Random seed: same input, options and seed give the same bytes.")] = D.seed,
    attributes: Annotated[Optional[List[str]], typer.Option("-a", "--attributes", metavar="LIST", help=f"Comma list of extra columns: {', '.join(ATTRIBUTES)} (repeated -a add up).")] = None,
    weight: Annotated[Optional[str], typer.Option("--weight", metavar="SOURCE", help="Density proportional to area times vertex-color:r|g|b|a or texture:r|g|b|a.")] = D.weight,
    objects: Annotated[Optional[List[str]], typer.Option("--object", metavar="NAME", help="Sample only this scene object (repeatable); for a USD stage, a prim path: the meshes at or below it.")] = D.objects,
    poisson: Annotated[bool, typer.Option("--poisson", help="Thin to a Poisson-disk set of exactly N points with the largest spacing reached.")] = D.poisson,
    radius: Annotated[Optional[float], typer.Option("--radius", metavar="R", help="Thin to a maximal Poisson-disk set with this minimum distance.")] = D.radius,
    exterior: Annotated[bool, typer.Option("--exterior", help="Only the exterior surface: what can be seen from outside the mesh (needs embreex).")] = D.exterior,
    method: Annotated[str, typer.Option("--method", metavar="METHOD", help="random (i.i.d., square-root warp) | stratified | sobol.")] = D.method,
    precision: Annotated[str, typer.Option("--precision", metavar="PRECISION", help="auto|float32|float64; auto keeps float32 unless it moves points by more than 1e-6 of the bounding-box diagonal.")] = D.precision,
    chunk_size: Annotated[Optional[int], typer.Option("--chunk-size", metavar="K", help="Points generated per chunk (memory/speed knob; never changes the output).")] = D.chunk_size,
    input_format: InputFormat = D.input_format,
    stable: Annotated[bool, typer.Option("--stable", help="Placement keyed to the faces themselves: points stay put when the mesh is edited elsewhere, renumbered or re-exported.")] = D.stable,
    shard: Annotated[Optional[str], typer.Option("--shard", metavar="K/M", help="Write only shard K (0-based) of M of the run's points; join shards with 'scatter merge'.")] = None,
    normalize: Annotated[str, typer.Option("--normalize", metavar="MODE", help="none | unit-cube | unit-sphere: points centred on the surface's box, scaled to fit [-1, 1] or the unit sphere.")] = D.normalize,
    crs: Annotated[Optional[str], typer.Option("--crs", metavar="EPSG:N|WKT", help="LAS/LAZ only: the coordinate system to record (an EPSG code needs pyproj).")] = None,
    volume: Annotated[bool, typer.Option("--volume", help="Points in space around the mesh, not on it: uniform in the padded box (labels: -a sdf,inside,winding,closest).")] = D.volume,
    near: Annotated[Optional[str], typer.Option("--near", metavar="SIGMA[,SIGMA...]", help="Near-surface points: a surface point plus a Gaussian offset of standard deviation SIGMA (implies --volume).")] = None,
    box_share: Annotated[Optional[float], typer.Option("--box-share", metavar="F", help="Share of the points uniform in the box, the rest near [default: 1 with --volume, 0 with --near].")] = D.box_share,
    padding: Annotated[Optional[float], typer.Option("--padding", metavar="P", help=f"The box: the surface's bounding box grown by P times its largest side [default: {PADDING}].")] = D.padding,
    sign: Annotated[Optional[str], typer.Option("--sign", metavar="winding|parity", help=f"Inside when the generalized winding number is >= 0.5 (robust on open meshes), or by a majority of ray parities [default: {SIGNS[0]}].")] = D.sign,
    edges: Annotated[Optional[str], typer.Option("--edges", metavar="F", help="Share (0..1) of the surface points drawn on sharp edges instead of faces (with --near: of the near points' surface points).")] = None,
    sharp_angle: Annotated[Optional[float], typer.Option("--sharp-angle", metavar="DEG", help="With --edges: an edge is sharp when its faces' normals are at least DEG degrees apart [default: 15]; boundary and non-manifold edges always are.")] = D.sharp_angle,
    near_edges: Annotated[Optional[str], typer.Option("--near-edges", metavar="SIGMA[,SIGMA...]", help="With --edges and --near: the sigmas of the near points of edge points [default: the --near sigmas].")] = None,
):
    """Never called: its signature is the declaration, as typer reads a command's."""


SAMPLE_OPTIONS = dict(inspect.signature(_declared).parameters)


def sample_options(*names, **redeclared):
    """A command's decorator: typer sees the sample options ``names`` after the command's
    own parameters, each as SAMPLE_OPTIONS declares it or with the annotation
    ``redeclared`` gives it (another help text); the command receives them as keyword
    arguments (``**given``)."""
    def declare(command):
        own = [p for p in inspect.signature(command).parameters.values() if p.kind != p.VAR_KEYWORD]
        taken = [SAMPLE_OPTIONS[n].replace(annotation=redeclared.get(n, SAMPLE_OPTIONS[n].annotation)) for n in names]
        command.__signature__ = inspect.Signature(own + taken)
        command.sample_options = names
        return command

    return declare


@app.command()
@sample_options(*SAMPLE_OPTIONS)
def sample(
    mesh: MeshArg,
    output: Annotated[Optional[str], typer.Option("-o", "--output", metavar="PATH", help="Output file; '-' or absent: standard output.")] = None,
    stats: Annotated[Optional[str], typer.Option("--stats", metavar="PATH", help="Write a JSON summary to this file ('-': standard error).")] = None,
    quiet: Annotated[bool, typer.Option("-q", "--quiet", help="No progress and no warnings.")] = False,
    **given,
):
    """Sample points on the surface of MESH (or, with --volume or --near, in the space around it).

    Faces are chosen with probability proportional to their area and the point inside
    a face comes from the square-root warp, so the points are uniform over the surface.
    Points of the default random method form an exchangeable sequence: any prefix of
    the output is itself a uniform sample.

    Examples:

      scatter sample bunny.obj -n 100000 -o bunny.ply

      scatter sample part.stl --density 50 -a normal -o part.csv

      cat mesh.ply | scatter sample - --input-format ply -n 1000 -f xyz

      scatter sample terrain.ply -n 1e9 --shard 3/8 -o part-3.ply

      scatter sample chair.obj --normalize unit-sphere --near 0.0707,0.0224 --box-share 0.06 -n 250000 -a sdf -o chair.npy
    """
    lean_trimesh()
    from . import api

    started = time.perf_counter()
    options = SampleOptions.of(given)
    run = api.sample_to(mesh, options, output, given["fmt"], given["ascii"], crs=given["crs"], warn=_warner(quiet),
                        progress=not quiet and sys.stderr.isatty())
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
    sharp_angle: Annotated[Optional[float], typer.Option("--sharp-angle", metavar="DEG", help="The angle of the sharp edges listed (what --edges samples) [default: 15].")] = None,
):
    """Faces, vertices, area, bounding box, degenerate faces, attributes, sharp edges and objects of MESH."""
    lean_trimesh()
    from .commands.info import describe, format_text

    if sharp_angle is not None and not 0 < sharp_angle <= 180:
        raise ScatterUsageError(f"--sharp-angle must be a number of degrees in (0, 180], not {sharp_angle:g}")
    report = describe(mesh, input_format=input_format, exterior=exterior, sharp_angle=sharp_angle)
    process.echo(json.dumps(report, indent=2) if as_json else format_text(report))


@app.command()
def check(
    mesh: Annotated[str, typer.Argument(metavar="MESH", help="Mesh file.")],
    count: Annotated[int, typer.Option("-n", "--count", metavar="N", parser=_count, help="Points per sampler.")] = 100000,
    seed: Annotated[int, typer.Option("--seed", metavar="S", help="Random seed.")] = 0,
    poisson: Annotated[bool, typer.Option("--poisson", help="Compare Poisson-disk sets of exactly N points.")] = False,
    radius: Annotated[Optional[float], typer.Option("--radius", metavar="R", help="Compare Poisson-disk sets of minimum distance R.")] = None,
):
    """Compare this tool's samples of MESH with pymeshlab's against the exact distribution.

    Exits 0 when scatter's points are consistent with the exact surface distribution
    (and so at least as good as pymeshlab's), 1 when not.
    """
    from .commands.check import run_check

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
    (pip install matplotlib).
    """
    from .commands.bench import run_bench

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


@app.command()
@sample_options(*(n for n in SAMPLE_OPTIONS if n != "input_format"))  # a batch finds its meshes by their suffixes
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
    quiet: Annotated[bool, typer.Option("-q", "--quiet", help="No progress, warnings, error lines or summary (the exit status and report still tell).")] = False,
    **given,
):
    """Sample many meshes: for each, what 'scatter sample MESH -o OUTPUT' writes.

    OUTPUT is TEMPLATE filled in per mesh. One bad mesh (an error, a crash, --timeout or
    --max-memory exceeded) fails alone; exit 1 when any failed.

    Examples:

      scatter batch models/ -o points/{rel}.ply -n 2048 -a normal -j 8

      find /data -name '*.glb' | scatter batch --from-list - -o out/{index:07d}.npy --skip-existing

      scatter batch /shared/meshes -o /shared/pts/{rel}.ply --engine dask --scheduler tcp://head:8786
    """
    from .engines.batch import run_batch  # (no NumPy here: the workers import it, and trimesh when a mesh needs it)

    result = run_batch(inputs or [], output, from_list=from_list, jobs=jobs, skip_existing=skip_existing,
                       timeout=timeout, max_memory=max_memory, report=report, engine=engine, scheduler=scheduler,
                       fmt=given["fmt"], ascii=given["ascii"], crs=given["crs"], options=SampleOptions.of(given), quiet=quiet,
                       progress=sys.stderr.isatty())
    if result["failed"]:
        raise typer.Exit(1)


@app.command(no_args_is_help=True)
def merge(
    parts: Annotated[List[str], typer.Argument(metavar="PART...", help="Point files of one format and column layout, in order.")],
    output: Annotated[str, typer.Option("-o", "--output", metavar="OUTPUT", help="The joined file ('-': standard output).")],
    fmt: Annotated[Optional[str], typer.Option("-f", "--format", metavar="FORMAT", help=f"Format of the parts and output ({', '.join(MERGEABLE)}) [default: from the suffixes].")] = None,
):
    """Join point files (such as the shards of one run) into one, in the order given.

    The shards of a run (scatter sample --shard K/M), merged in order, are that run's
    output byte for byte. Parts of different formats or columns are an error naming the
    first one that differs.

      scatter merge part-0.ply part-1.ply part-2.ply -o whole.ply
    """
    from .commands.merge import merge as join

    join(parts, output, fmt)


@app.command(no_args_is_help=True)
@sample_options(
    "count", "density", "seed", "attributes", "weight", "objects", "poisson", "radius", "method", "exterior", "stable",
    "normalize", "edges", "sharp_angle",
    count=Annotated[Optional[int], typer.Option("-n", "--count", metavar="N", parser=_count, help="Points sampled per mesh [default: 20000].")],
    attributes=Annotated[Optional[List[str]], typer.Option("-a", "--attributes", metavar="LIST", help="Attributes sampled on meshes, which colour them (repeated -a add up) [default: normal, and sharp with --edges].")],
)
def preview(
    inputs: Annotated[Optional[List[str]], typer.Argument(metavar="INPUT...", help="Point files, meshes and folders (searched recursively).", show_default=False)] = None,
    output: Annotated[str, typer.Option("-o", "--output", metavar="SHEET.png", help="The contact sheet; with {page} in the name, one sheet per --per-page inputs.")] = ...,
    from_list: Annotated[Optional[str], typer.Option("--from-list", metavar="FILE", help="Read input paths, one a line, from FILE ('-': standard input).")] = None,
    size: Annotated[int, typer.Option("--size", metavar="PX", help="Thumbnail side in pixels.")] = 256,
    columns: Annotated[Optional[int], typer.Option("--columns", metavar="C", help="Cells per row [default: a square sheet].")] = None,
    views: Annotated[Optional[List[str]], typer.Option("--view", metavar="VIEW", help="iso | front | side | top (repeatable: views side by side) [default: iso].")] = None,
    per_page: Annotated[int, typer.Option("--per-page", metavar="K", help="Inputs per sheet.")] = 100,
    quiet: Annotated[bool, typer.Option("-q", "--quiet", help="No error line per failed input (the exit status and the sheet still tell).")] = False,
    **given,
):
    """Contact sheets: one captioned thumbnail per point file or mesh, drawn on the CPU.

    Each input is seen from a three-quarter view of its bounding box (or --view), its
    points coloured by colour, inside/sdf, normals or height. A bad input gets a
    crossed-out cell with its error; the sheet is still written and the exit is 1.

      scatter preview points/ -o sheet.png

      scatter preview meshes/ -n 5000 --view front --view top -o sheets/page-{page}.png
    """
    lean_trimesh()
    from .commands.preview import preview as draw_sheets
    from .commands.preview import summary

    options = SampleOptions.of(given).as_dict()
    def error_line(message):
        print(f"error: {message}", file=sys.stderr, flush=True)

    sheets = draw_sheets(inputs or [], output, size=size, columns=columns, views=views or ("iso",),
                         per_page=per_page, from_list=from_list, warn=None if quiet else error_line, **options)
    if sheets.failed:
        if not quiet:
            print(summary(sheets), file=sys.stderr)
        raise typer.Exit(1)


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
    if ctx.invoked_subcommand is None:  # no command: say how to ask for help, exit 2
        typer.echo(ctx.get_usage(), err=True)
        typer.echo(f"Try '{ctx.command_path} --help' for the commands.", err=True)
        raise typer.Exit(2)


def command():
    """The click command of ``scatter``, with usage lines as a user reads them: a required
    argument is written ``MESH``, not ``{MESH}``; the examples of ``--help`` as written
    (one command a line, not wrapped); completion options that take the shell."""
    root = typer.main.get_command(app)
    for cmd in [root, *getattr(root, "commands", {}).values()]:
        cmd.help = examples_kept(cmd.help)
        for param in cmd.params:
            if param.param_type_name == "argument" and param.required and param.metavar:
                param.get_usage_pieces = lambda ctx, name=param.metavar: [name]
    root.params = [completion_option(p) if p.name in COMPLETION else p for p in root.params]
    return root


def examples_kept(text):
    """``text`` (a command's help) with each indented paragraph, an example command, marked
    for click to print as it is ("\\b"), not re-wrapped to the terminal's width."""
    if not text:
        return text
    paragraphs = inspect.cleandoc(text).split("\n\n")
    return "\n\n".join("\b\n" + p if p.startswith("  ") else p for p in paragraphs)


SHELLS = ("bash", "zsh", "fish", "powershell", "pwsh")
COMPLETION = {"install_completion": "Install completion for SHELL [default: the current shell].",
              "show_completion": "Print the completion script for SHELL [default: the current shell], to copy it "
                                 "or customize the installation."}


def completion_option(typer_option):
    """typer's ``--install-completion`` or ``--show-completion`` (a flag: the shell it
    detects) taking the shell as a value, ``--show-completion zsh``; given alone, the
    value is "" (:func:`shell_named`): the shell detected."""

    def done(ctx, param, value):
        if value is None or ctx.resilient_parsing:
            return
        if value and value not in SHELLS:
            raise typer.BadParameter(f"'{value}' is not a shell completion is made for (choose from: {', '.join(SHELLS)})",
                                     ctx, param)
        try:
            typer_option.callback(ctx, param, value or True)  # prints or installs, then exits
        except SystemExit as exc:
            raise typer.Exit(exc.code or 0) from None

    return type(typer_option)(param_decls=typer_option.opts, is_flag=False, expose_value=False, is_eager=True,
                              callback=done, metavar="[SHELL]", help=COMPLETION[typer_option.name])


def shell_named(argv):
    """``argv`` with "" after a completion option given without its shell."""
    options = {"--" + name.replace("_", "-") for name in COMPLETION}
    argv = list(argv)
    for i in reversed(range(len(argv))):
        if argv[i] in options and (i + 1 == len(argv) or argv[i + 1].startswith("-")):
            argv.insert(i + 1, "")
    return argv


def main(argv=None) -> int:
    """Run ``scatter`` on ``argv`` (default: the process's arguments); returns the exit code."""
    argv = list(sys.argv[1:] if argv is None else argv)
    return process.run_command(command(), shell_named(argv))


def run():
    """The ``scatter`` console script: :func:`main`, then exit at once."""
    process.exit_now(main())
