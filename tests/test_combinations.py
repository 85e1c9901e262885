"""Where features meet: every output format, every kind of run, every attribute it accepts.

Each combination is written in this process (``api.write``, what ``scatter sample -o``
does after its checks), read back by a reader that is not ours where one exists (NumPy
for NPY and the text formats, trimesh for PLY, pypcd4 for PCD, laspy for LAS/LAZ, pxr for
USD), and every column is compared with the run's in-memory ``Samples`` within the
format's precision; the file's columns must be those the contract names, in its order,
none dropped or renamed. A combination the contract refuses is a usage error: exit 2 and
one ``error:`` line (``scatter_cli.cli.main``, in this process too).
"""

from __future__ import annotations

import dataclasses
import functools
import itertools

import numpy as np
import pytest

import scatter_cli.api as api
from scatter_cli.run.options import SampleOptions
from scatter_cli.writers import run_precision

from .batchtools import command_in_process
from .conftest import SAMPLES
from .test_pcd import read_pcd as read_pcd_fields

BOX, TRUCK = str(SAMPLES / "boxtextured.glb"), str(SAMPLES / "cesiummilktruck.glb")
COUNT = 48

# The contract's columns (CLI.md, "Output formats" and "Volume samples"), in its order:
# attribute key -> its columns.
CONTRACT = {
    "points": ("x", "y", "z"),
    "normal": ("nx", "ny", "nz"),
    "orient": ("qx", "qy", "qz", "qw"),
    "sdf": ("sdf",),
    "inside": ("inside",),
    "winding": ("winding",),
    "closest": ("cx", "cy", "cz"),
    "face": ("face_index",),
    "bary": ("bary0", "bary1", "bary2"),
    "color": ("red", "green", "blue", "alpha"),
    "uv": ("u", "v"),
    "object": ("object_index",),
    "sharp": ("sharp",),
}
SURFACE = "normal,face,bary,color,uv,object,orient,sharp"
VOLUME = "sdf,inside,winding,closest,face,object,sharp"

# kind of run -> (mesh, options with every attribute it accepts); the kinds that meet in
# pairs are here too (PAIRS says which pairs the contract allows)
KINDS = {
    "surface": (BOX, dict(attributes=SURFACE)),
    "smooth": (BOX, dict(attributes=SURFACE.replace("normal", "smooth-normal"))),
    "poisson": (BOX, dict(poisson=True, attributes=SURFACE)),
    "stable": (BOX, dict(stable=True, attributes=SURFACE)),
    "exterior": (BOX, dict(exterior=True, attributes=SURFACE)),
    "poisson-exterior": (BOX, dict(poisson=True, exterior=True, attributes=SURFACE)),
    "stable-exterior": (BOX, dict(stable=True, exterior=True, attributes=SURFACE)),
    "scene": (TRUCK, dict(attributes=SURFACE.replace(",uv", ""))),  # (one of its objects has no UVs)
    "edges": (BOX, dict(edges=0.5, attributes=SURFACE)),
    "volume": (TRUCK, dict(volume=True, attributes=VOLUME)),
    "near": (BOX, dict(volume=True, near=(0.05, 0.01), box_share=0.25, attributes=VOLUME)),
    "near-edges": (BOX, dict(near=(0.05,), edges=0.5, near_edges=(0.01,), attributes=VOLUME)),
}
# the output's frame and precision: what the run writes with no option, float64, normalized
FRAMES = {"plain": {}, "float64": dict(precision="float64"), "unit-cube": dict(normalize="unit-cube")}
# format variant -> (format, file name, --ascii, --crs)
OUTPUTS = {
    "ply": ("ply", "out.ply", False, None),
    "ply-ascii": ("ply", "out.ply", True, None),
    "csv": ("csv", "out.csv", False, None),
    "xyz": ("xyz", "out.xyz", False, None),
    "npy": ("npy", "out.npy", False, None),
    "pcd": ("pcd", "out.pcd", False, None),
    "pcd-ascii": ("pcd", "out.pcd", True, None),
    "las": ("las", "out.las", False, None),
    "las-crs": ("las", "out.las", False, "EPSG:2056"),
    "laz": ("laz", "out.laz", False, None),
    "laz-crs": ("laz", "out.laz", False, "EPSG:2056"),
    "usda": ("usd", "out.usda", False, None),
    "usdc": ("usd", "out.usdc", False, None),
}


@functools.cache
def prepared(kind, frame, precision):
    """(run, its Samples) of a kind of run in a frame, at ``precision`` (what the format
    asks for: LAS takes float64 points whatever the run's)."""
    mesh, options = KINDS[kind]
    o = SampleOptions(count=COUNT, seed=5, **options, **FRAMES[frame])
    run = api.prepare(mesh, options=dataclasses.replace(o, precision=precision))
    return run, run.collect()


def contract_columns(samples):
    """name -> (n,) array of every column of ``samples``, in the contract's order."""
    out = {}
    for key, names in CONTRACT.items():
        if key == "points" or key in samples.attributes:
            data = samples.points if key == "points" else samples.attributes[key]
            out.update(zip(names, data.reshape(len(samples), -1).T))
    return out


# -- the readers -------------------------------------------------------------------------
# Each returns (the file's names of its columns, in its order; contract column name ->
# (n,) array; how far its coordinates may lie from the run's).

def read_npy(path, want):
    a = np.load(path)
    return list(a.dtype.names), {n: a[n] for n in a.dtype.names}, 0.0


def read_ply(path, want):
    import trimesh

    raw = trimesh.load(path, process=False).metadata["_ply_raw"]["vertex"]["data"]
    names = list(raw.dtype.names if hasattr(raw, "dtype") else raw)
    return names, {n: np.asarray(raw[n]).reshape(-1) for n in names}, 0.0


def read_text(path, want, sep, header):
    with open(path) as f:
        names = f.readline().strip().split(sep) if header else None
    table = np.loadtxt(path, delimiter=sep, skiprows=1 if header else 0, ndmin=2, dtype=np.float64)
    if names is None:  # XYZ: no names, the contract's columns by position
        assert table.shape[1] == len(want), f"xyz: {table.shape[1]} columns, the contract has {len(want)}"
        names = list(want)
    # each column as the type it should be: a text format promises the exact value back
    return names, {n: table[:, j].astype(want[n].dtype) if n in want else table[:, j] for j, n in enumerate(names)}, 0.0


PCL_NAMES = {"nx": "normal_x", "ny": "normal_y", "nz": "normal_z"}


def read_pcd(path, want):
    with open(path, "rb") as f:
        names = next(line for line in f if line.startswith(b"FIELDS")).decode().split()[1:]
    fields = read_pcd_fields(path)
    pcl_to_contract = {pcl: ours for ours, pcl in PCL_NAMES.items()}
    return names, {pcl_to_contract.get(n, n): column for n, column in fields.items()}, 0.0


def pcd_names(names):
    """The contract's columns as PCD fields: PCL's normals, one packed ``rgb``."""
    out = [PCL_NAMES.get(n, n) for n in names if n not in ("green", "blue", "alpha")]
    return ["rgb" if n == "red" else n for n in out]


def read_las(path, want):
    import laspy

    las = laspy.read(path)
    rgb = list(CONTRACT["color"][:3]) if las.point_format.id == 7 else []
    names = ["x", "y", "z", *rgb, *las.point_format.extra_dimension_names]
    return names, {n: np.asarray(las[n]) for n in names}, las.header.scales.max() / 2 * (1 + 1e-9)


def las_names(names):
    """The contract's columns in a LAS file: x y z, red green blue as the standard
    fields (point format 7), every other column an Extra Bytes field of its own."""
    rgb = [n for n in CONTRACT["color"][:3] if n in names]
    return ["x", "y", "z", *rgb, *(n for n in names if n not in ("x", "y", "z", *rgb))]


# USD primvar -> (the contract's columns it holds, the factor to their scale)
USD_PRIMVARS = {"normals": (CONTRACT["normal"], 1), "st": (CONTRACT["uv"], 1), "bary": (CONTRACT["bary"], 1),
                "displayColor": (CONTRACT["color"][:3], 255), "displayOpacity": (("alpha",), 255)}


def read_usd(path, want):
    from pxr import Usd, UsdGeom

    stage = Usd.Stage.Open(str(path))
    prims = [p for p in stage.Traverse() if p.IsA(UsdGeom.Points) or p.IsA(UsdGeom.PointInstancer)]
    assert len(prims) == 1, prims
    prim = prims[0]
    columns = {}
    if prim.IsA(UsdGeom.Points):
        names, local = ["points"], UsdGeom.Points(prim).GetPointsAttr().Get()
    else:
        inst = UsdGeom.PointInstancer(prim)
        names, local = ["positions", "orientations"], inst.GetPositionsAttr().Get()
        q = [[*x.GetImaginary(), x.GetReal()] for x in inst.GetOrientationsfAttr().Get()]
        columns.update(zip(CONTRACT["orient"], np.array(q, np.float32).reshape(-1, 4).T))
    matrix = np.array(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(Usd.TimeCode.Default()))

    def world(value):  # USD: row vectors
        return np.asarray(value, dtype=np.float64).reshape(-1, 3) @ matrix[:3, :3] + matrix[3, :3]

    columns.update(zip("xyz", world(local).T))
    # float32 values: as they are (float32 runs), or relative to a translate (float64 runs)
    within = 0.0 if want["x"].dtype == np.float32 else np.finfo(np.float32).eps * np.abs(np.asarray(local)).max()
    for primvar in UsdGeom.PrimvarsAPI(prim).GetAuthoredPrimvars():
        name = primvar.GetPrimvarName()
        names.append(name)
        assert primvar.GetInterpolation() == UsdGeom.Tokens.vertex, name
        value = np.asarray(primvar.Get())
        if name == "closest":  # a point3f primvar: in the points' space
            columns.update(zip(CONTRACT["closest"], world(value).T))
        elif name in USD_PRIMVARS:
            cols, scale = USD_PRIMVARS[name]
            columns.update(zip(cols, (value.reshape(len(value), -1) * scale).T))
        else:
            columns[name] = value
    return names, columns, within


def usd_names(names):
    """What a USD file holds of the contract's columns: ``points`` (``positions`` and
    ``orientations`` with orient), and one primvar per other column (a group of columns:
    one primvar of vectors)."""
    given = set(names)
    out = {"positions", "orientations"} if "qw" in given else {"points"}
    out |= {primvar for primvar, (cols, _) in USD_PRIMVARS.items() if cols[0] in given}
    out |= {"closest"} if "cx" in given else set()
    grouped = {c for cols in CONTRACT.values() if len(cols) > 1 for c in cols}
    return out | {n for n in given if n not in grouped}


READERS = {  # format -> (reader, the names its files give the contract's columns)
    "npy": (read_npy, list),
    "ply": (read_ply, list),
    "csv": (functools.partial(read_text, sep=",", header=True), list),
    "xyz": (functools.partial(read_text, sep=None, header=False), list),
    "pcd": (read_pcd, pcd_names),
    "las": (read_las, las_names),
    "laz": (read_las, las_names),
    "usd": (read_usd, usd_names),
}


def assert_agrees(fmt, name, got, want, within):
    """``got``, the column ``name`` read from a file of ``fmt``, holds ``want`` as the
    format stores it: exactly (binary and text formats, in their own type), coordinates
    within ``within`` (LAS: half its scale; USD: float32 relative to a translate), LAS's
    float32 Extra Bytes and 16-bit colour, USD's float32 values and 0..1 colours."""
    where = f"{fmt}: column {name}"
    got = np.asarray(got)
    assert got.shape == want.shape, f"{where}: {got.shape} values, want {want.shape}"
    las, usd = fmt in ("las", "laz"), fmt == "usd"
    if (las or usd) and (name in CONTRACT["points"] or usd and name in CONTRACT["closest"]):
        assert np.abs(got - want).max(initial=0) <= within, where
    elif las and name in CONTRACT["color"][:3]:
        assert_equal(got, want.astype(np.uint16) * 257, where)
    elif usd and name in CONTRACT["color"]:
        assert_equal(np.rint(got), want, where)
    elif (las or usd and name not in ("sdf", "winding")) and want.dtype.kind == "f":
        assert_equal(got, want.astype(np.float32), where)
    else:
        assert_equal(got, want, where)
        if fmt in ("npy", "ply", "pcd") and name not in CONTRACT["color"]:
            assert got.dtype == want.dtype, f"{where}: stored as {got.dtype}, not {want.dtype}"


def assert_equal(got, want, where):
    assert np.array_equal(got, want), f"{where}: {np.count_nonzero(got != want)} of {len(want)} values differ"


def check_file(fmt, path, samples):
    """Read ``path`` back and hold every column to ``samples``'s; the file's names are
    the contract's, in its order (a set for USD), none dropped, renamed or added."""
    want = contract_columns(samples)
    reader, naming = READERS[fmt]
    names, got, within = reader(path, want)
    expected = naming(list(want))
    if isinstance(expected, set):
        assert set(names) == expected, f"{fmt}: holds {sorted(names)}, the contract says {sorted(expected)}"
    else:
        assert names == expected, f"{fmt}: holds {names}, the contract says {expected}"
    for name, column in want.items():
        assert name in got, f"{fmt}: column {name} is missing"
        assert_agrees(fmt, name, got[name], column, within)


def write_and_check(tmp_path, kind, frame, variant):
    """Write the run ``kind`` in ``frame`` to the output ``variant``, check the file;
    returns the run's Samples."""
    fmt, name, ascii, crs = OUTPUTS[variant]
    run, samples = prepared(kind, frame, run_precision(fmt, FRAMES[frame].get("precision", "auto")))
    path = tmp_path / name
    api.write(run, path, fmt, ascii, crs=crs)
    check_file(fmt, path, samples)
    if fmt in ("las", "laz"):
        import laspy

        header = laspy.read(path).header
        assert header.point_format.id == (7 if "color" in samples.attributes else 6)
        assert (header.parse_crs() is not None) == (crs is not None)
    return samples


@pytest.mark.parametrize("variant", OUTPUTS)
@pytest.mark.parametrize("kind", KINDS)
def test_every_column_of_every_run_reads_back(tmp_path, kind, variant):
    samples = write_and_check(tmp_path, kind, "plain", variant)
    assert len(samples) == COUNT and len(samples.attributes) == len(KINDS[kind][1]["attributes"].split(","))


# A frame or precision changes the values the writers get, not which columns: in each,
# one kind of run per set of columns (every surface attribute, a scene's objects, a
# scene's volume labels, near points with sharp edges) in every output.
FRAME_KINDS = ("surface", "scene", "volume", "near-edges")


@pytest.mark.slow
@pytest.mark.parametrize("variant", OUTPUTS)
@pytest.mark.parametrize("frame", ["float64", "unit-cube"])
@pytest.mark.parametrize("kind", FRAME_KINDS)
def test_every_column_reads_back_in_every_frame(tmp_path, kind, frame, variant):
    write_and_check(tmp_path, kind, frame, variant)


def drop_primvars(monkeypatch, *keys):
    import scatter_cli.writers.usd as usd

    monkeypatch.setattr(usd, "PRIMVARS", {k: v for k, v in usd.PRIMVARS.items() if k not in keys})


def rename_in_ply_header(monkeypatch, old, new):
    import scatter_cli.writers.ply as ply

    header = ply.header
    monkeypatch.setattr(ply, "header", lambda *a, **k: header(*a, **k).replace(old, new))


def no_pcd_alpha(monkeypatch):
    import scatter_cli.writers.pcd as pcd

    pack = pcd.pack_rgb
    monkeypatch.setattr(pcd, "pack_rgb", lambda color: pack(color) & np.uint32(0xFFFFFF))


def short_text(monkeypatch):
    import scatter_cli.writers.text as text

    init = text.TextEncoder.__init__

    def fewer_digits(self, *args):
        init(self, *args)
        self.row = self.row.replace("%r", "%.15g")

    monkeypatch.setattr(text.TextEncoder, "__init__", fewer_digits)


BROKEN = {  # a writer that drops, renames or alters a column -> the run and output it breaks
    "usd drops the labels": (lambda mp: drop_primvars(mp, "sdf", "inside", "winding", "closest"), "near", "usda"),
    "usd drops sharp": (lambda mp: drop_primvars(mp, "sharp"), "edges", "usdc"),
    "ply renames face_index": (lambda mp: rename_in_ply_header(mp, b"face_index", b"face"), "surface", "ply"),
    "pcd loses alpha": (no_pcd_alpha, "scene", "pcd"),
    "csv short of digits": (short_text, "near", "csv"),
}


@pytest.mark.parametrize("broken", BROKEN)
def test_a_dropped_renamed_or_altered_column_fails_the_check(tmp_path, monkeypatch, broken):
    breaking, kind, variant = BROKEN[broken]
    write_and_check(tmp_path, kind, "plain", variant)
    breaking(monkeypatch)
    with pytest.raises(AssertionError):
        write_and_check(tmp_path, kind, "plain", variant)


# -- combinations the contract refuses: exit 2 ---------------------------------------------

def cli_argv(options):
    """The command line's spelling of API ``options``: ``--near-edges 0.01`` for
    ``near_edges=(0.01,)``, ``--poisson`` for ``poisson=True``, ``-a LIST``."""
    argv = []
    for key, value in options.items():
        flag = "-a" if key == "attributes" else "--" + key.replace("_", "-")
        if value is True:
            argv.append(flag)
        else:
            argv += [flag, ",".join(map(str, value)) if isinstance(value, tuple) else str(value)]
    return argv


def assert_usage_error(tmp_path, capsys, mesh, argv, *words, output="out.npy"):
    """``scatter sample MESH ARGV -o OUTPUT`` exits 2 with one ``error:`` line naming
    ``words``, and writes nothing."""
    capsys.readouterr()
    code = command_in_process([str(a) for a in ["sample", mesh, *argv, "-n", 10, "-o", tmp_path / output]])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("error: ") and err.count("\n") == 1, (argv, code, err)
    assert all(w in err for w in words), (words, err)
    assert not list(tmp_path.iterdir())


# the attributes a run takes (CLI.md, "scatter sample" and "Volume samples")
TAKES = {"surface": ("normal", "smooth-normal", "face", "bary", "color", "uv", "object", "orient", "sharp"),
         "volume": ("sdf", "inside", "winding", "closest", "face", "object", "sharp")}


def kind_of_points(options):
    return "volume" if options.get("volume") or options.get("near") else "surface"


@pytest.mark.parametrize("kind", KINDS)
def test_an_attribute_the_run_does_not_take_is_a_usage_error(tmp_path, capsys, kind):
    mesh, options = KINDS[kind]
    points = kind_of_points(options)
    refused = [a for a in itertools.chain(*TAKES.values()) if a not in TAKES[points]]
    for name in refused:
        assert_usage_error(tmp_path, capsys, mesh, cli_argv({**options, "attributes": name}), repr(name), "runs only")
    assert set(options["attributes"].split(",")) <= set(TAKES[points])


# The kinds of run two at a time: the pairs the contract refuses, each with an option its
# error names; every other pair is a kind of run above.
MODIFIERS = {"poisson": dict(poisson=True), "stable": dict(stable=True), "exterior": dict(exterior=True),
             "edges": dict(edges=0.5), "volume": dict(volume=True), "near": dict(near=(0.05,))}
REFUSED = {("poisson", "stable"), ("poisson", "edges"), ("poisson", "volume"), ("poisson", "near"),
           ("stable", "edges"), ("stable", "volume"), ("stable", "near"), ("exterior", "edges"),
           ("exterior", "volume"), ("exterior", "near"), ("edges", "volume")}


@pytest.mark.parametrize("pair", list(itertools.combinations(MODIFIERS, 2)), ids="+".join)
def test_two_kinds_of_run_meet_or_are_a_usage_error(tmp_path, capsys, pair):
    if pair in REFUSED:
        argv = cli_argv({**MODIFIERS[pair[0]], **MODIFIERS[pair[1]]})
        assert_usage_error(tmp_path, capsys, BOX, argv, f"--{pair[0]}")
    else:
        assert [k for k, (_, o) in KINDS.items() if set(o) & set(MODIFIERS) == set(pair)], f"no kind of run {pair}"


# output options by format: --ascii for PLY and PCD, --crs for LAS and LAZ (CLI.md)
OUTPUT_OPTIONS = {"--ascii": (["--ascii"], ("ply", "pcd")), "--crs": (["--crs", "EPSG:2056"], ("las", "laz"))}


@pytest.mark.parametrize("option", OUTPUT_OPTIONS)
@pytest.mark.parametrize("variant", [v for v in OUTPUTS if "-" not in v and v != "usdc"])
def test_an_output_option_of_another_format_is_a_usage_error(tmp_path, capsys, option, variant):
    argv, formats = OUTPUT_OPTIONS[option]
    fmt, name, _, _ = OUTPUTS[variant]
    if fmt in formats:  # the matrix above writes it
        assert f"{variant}-{option.strip('-')}" in OUTPUTS
    else:
        assert_usage_error(tmp_path, capsys, BOX, argv, option, output=name)


# a check taken away -> the test above that must then fail, and its case
MISSING_CHECKS = {
    "attributes": ("scatter_cli.run.options.check_attributes", test_an_attribute_the_run_does_not_take_is_a_usage_error,
                   ("near",)),
    "volume options": ("scatter_cli.run.options._check_volume", test_two_kinds_of_run_meet_or_are_a_usage_error,
                       (("stable", "volume"),)),
    "edges options": ("scatter_cli.run.options._check_edges", test_two_kinds_of_run_meet_or_are_a_usage_error,
                      (("exterior", "edges"),)),
    "output options": ("scatter_cli.writers.check_output", test_an_output_option_of_another_format_is_a_usage_error,
                       ("--ascii", "csv")),
}


@pytest.mark.parametrize("missing", MISSING_CHECKS)
def test_a_missing_check_fails_its_test(tmp_path, capsys, monkeypatch, missing):
    target, test, case = MISSING_CHECKS[missing]
    monkeypatch.setattr(target, lambda *args, **kwargs: None)
    with pytest.raises(AssertionError):
        test(tmp_path, capsys, *case)
