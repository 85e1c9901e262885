"""Every compiled kernel gives the bytes of its NumPy twin, over the same cases.

One parametrized test: each case runs once with the kernels as built and once with the
kernel it exercises switched off in every module native.KERNELS says holds it (as
SCATTER_NUMPY=1 leaves them), and the two results must be byte-identical. The kernel's
functions are watched: the NumPy run must call none of them (else some module holds the
kernel outside the registry), and every function the kernel exports has a case that must
call it (CALLED_BY). A kernel made one ulp wrong fails the same comparison, and so does a
registry that leaves a holder out (the broken variants).

Every other test runs with the kernels (CI builds them), so these are what carries those
results over to the NumPy path that runs where no C compiler was found.
"""

import importlib
import os

import numpy as np
import pytest
import trimesh

import scatter_cli
from scatter_cli.volume import distance, parity, winding
from scatter_cli.sampling.exterior import enclosure, rayscene
from scatter_cli.core import native
from scatter_cli.sampling import normals, plan as sampling
from scatter_cli.sampling.poisson import pairs, thinning
from scatter_cli.loading.load import load_surface
from scatter_cli.surface.model import Geometry, Instance, Surface

from . import exterior_scenes as es
from .conftest import SAMPLES, awkward_mesh, spread_triangles, triangles_mesh

REQUIRED = os.environ.get("SCATTER_REQUIRE_KERNELS", "") not in ("", "0")

# -- sampling (_csampling) -----------------------------------------------------------------


def with_degenerate_faces():
    tri, _ = spread_triangles(np.arange(-9, 4))
    tri[3] = [[0, 0, 5], [1, 0, 5], [2, 0, 5]]  # collinear: never chosen
    tri[7] = [[1e6, 1e6, 1e6], [1e6 + 1e-3, 1e6, 1e6], [1e6, 1e6 + 2e-3, 1e6]]  # far away, tiny
    return triangles_mesh(tri)


def moved_instances():
    """One geometry placed three times, one of them with a non-uniform scale."""
    mesh = trimesh.creation.icosphere(subdivisions=2)
    g = Geometry("ball", mesh.vertices, mesh.faces)
    stretch = np.diag([3.0, 0.5, 1.0, 1.0])
    stretch[:3, 3] = [10, 0, 0]
    shift = np.eye(4)
    shift[:3, 3] = [0, -7.25, 1e3]
    return Surface([g], [Instance("a", 0, None), Instance("b", 0, stretch), Instance("c", 0, shift)], "balls")


def one_moved_mesh():
    mesh = trimesh.load(SAMPLES / "koala.obj", process=False)
    m = np.array([[0.0, 2.0, 0.0, 1.5], [-1.0, 0.0, 0.0, 3.0], [0.0, 0.0, 0.25, -2.0], [0.0, 0.0, 0.0, 1.0]])
    g = Geometry("koala", mesh.vertices, mesh.faces)
    return Surface([g], [Instance("moved", 0, m)], "moved koala")


MESHES = {
    "skull": lambda: str(SAMPLES / "skull.ply"),
    "degenerate": with_degenerate_faces,
    "instances": moved_instances,
    "moved": one_moved_mesh,
    "truck": lambda: str(SAMPLES / "cesiummilktruck.glb"),
    "colors": lambda: str(SAMPLES / "boxvertexcolors.glb"),
    "textured": lambda: str(SAMPLES / "boxtextured.glb"),
    "koala": lambda: str(SAMPLES / "koala.obj"),
    "hemisphere": lambda: str(SAMPLES / "hemisphere.off"),
    "pediment": lambda: str(SAMPLES / "pediment_join_plate_12.stl"),
}


def surface_of(name):
    mesh = MESHES[name]()
    return mesh if isinstance(mesh, Surface) else load_surface(mesh)


def sample_bytes(name, **options):
    """Every array of a run, as bytes, and its d_min where thinning gives one."""
    s = scatter_cli.sample(surface_of(name), **options)
    out = {"points": s.points.tobytes(), "dtype": str(s.points.dtype), "d_min": s.info.get("d_min")}
    return out | {k: v.tobytes() for k, v in s.attributes.items()}


def sampling_case(name, **options):
    return lambda: sample_bytes(name, **(dict(count=20_011, seed=7, precision="float64", chunk_size=4096) | options))


def face_order_case(name):
    """On large meshes the kernel computes a chunk's points in face order; forced on here,
    it must not change a byte, whatever the chunk size."""

    def run():
        plan = sampling.SamplePlan(surface_of(name))
        plan.in_face_order = sampling._kernel is not None
        whole = plan.draw(0, 30_011, 3, want_bary=True)
        parts = [plan.draw(a, min(a + 7_000, 30_011), 3, want_bary=True) for a in range(0, 30_011, 7_000)]
        fields = ("points", "face", "bary", "instance")
        return {f: getattr(whole, f).tobytes() for f in fields} | {
            f + "-parts": np.concatenate([getattr(p, f) for p in parts]).tobytes() for f in fields}

    return run


def normals_case(seed, center):
    def run():
        v, f = awkward_mesh(seed)
        with np.errstate(all="ignore"):
            return {"normals": normals.face_normals(v, f, center).tobytes()}

    return run


def stream_case(seed, start):
    """The kernel draws PCG64DXSM itself: any start, far into the stream, must match NumPy."""

    def run():
        d = sampling.SamplePlan(surface_of("koala")).draw(start, start + 1000, seed, want_bary=True)
        return {f: getattr(d, f).tobytes() for f in ("points", "face", "bary")}

    return run


# -- thinning (_cthinning) -----------------------------------------------------------------


def point_sets():
    rng = np.random.default_rng(11)
    sphere = rng.normal(size=(20_000, 3))
    sphere /= np.linalg.norm(sphere, axis=1, keepdims=True)
    clustered = np.repeat(rng.random((200, 3)), 40, axis=0) + rng.normal(scale=1e-4, size=(8000, 3))
    duplicated = np.repeat(rng.random((500, 3)), 30, axis=0)  # all but one of each over the cap
    wall = rng.random((10_000, 3)) * [1, 1, 0]
    wall[::2, 2] = 0.013  # two sheets closer than the radius
    far = rng.random((3000, 3)) * 1e-3 + 1e7  # huge coordinates, small extent
    # cells along a diagonal: their box is too large for the kernel's table of cells, which
    # then searches the sorted cell list instead
    line = rng.random((4000, 1)) * [1.0, 1.0, 1.0] + rng.normal(scale=1e-3, size=(4000, 3))
    # about 160 neighbours a point: more pairs than the kernel lists, so it finds them again
    dense = rng.random((20_000, 3)) * [1, 1, 0]
    return {"sphere": (sphere, 0.05), "clustered": (clustered, 0.02), "duplicated": (duplicated, 0.03),
            "wall": (wall, 0.02), "far": (far, 1e-4), "line": (line, 0.003), "dense": (dense, 0.05)}


def thinning_case(name):
    def run():
        points, radius = point_sets()[name]
        by_radius = thinning.thin_by_radius(points, radius)
        count = max(2, len(by_radius) // 2)  # (the count is the same on both paths when the radii agree)
        idx, d_min = thinning.thin_to_count(points, count, 1.0)  # the area only scales the first radius tried
        return {"by_radius": by_radius.tobytes(), "by_count": idx.tobytes(), "d_min": d_min}

    return run


def plain_loops_case(name):
    """Thinning with the kernel's plain distance loops (SCATTER_NO_AVX512=1's choice; the
    only loops on a CPU without AVX-512)."""
    run = thinning_case(name)

    def plain():
        if pairs._kernel is None:
            return run()
        pairs._kernel.use_avx512(False)
        try:
            return run()
        finally:
            native.kernel("_cthinning")  # back to the environment's choice

    return plain


def pairs_case(name):
    def run():
        points, radius = point_sets()[name]
        i, j, d = pairs.all_pairs(points, radius)
        key = np.lexsort((j, i))
        return {"i": i[key].astype(np.int64).tobytes(), "j": j[key].astype(np.int64).tobytes(),
                "d": d[key].tobytes()}

    return run


# -- stable placement (_cstable) ------------------------------------------------------------


def stable_case(name, **kw):
    def run():
        s = scatter_cli.sample(str(SAMPLES / name), stable=True, attributes=("face", "bary", "object"), **kw)
        return {"points": s.points.tobytes()} | {k: v.tobytes() for k, v in s.attributes.items()}

    return run


# -- fast readers (_creaders): without them trimesh reads the file ---------------------------


def reader_case(fmt, mesh, **tables):
    """A sample mesh re-saved as ``fmt`` (a text format the kernel parses), loaded for a
    plain job: the same world corners and names."""

    def run(tmp_path):
        from .test_readers import resave

        tmp_path.mkdir()
        s = load_surface(str(resave(SAMPLES / mesh, fmt, tmp_path)), plain=True, **tables)
        out = {"names": [i.name for i in s.instances]}
        for k, inst in enumerate(s.instances):
            out[f"corners-{k}"] = s.world_vertices(inst)[s.geometries[inst.geometry].faces].tobytes()
        return out

    return run


# -- ray scenes (_cembree): without it embreex builds the scene ------------------------------


def rays_case(scene):
    def run():
        meshes = [(m.vertices, m.faces.astype(np.int64)) for m in getattr(es, scene)()[0].dump()]
        rs = rayscene.RayScene()
        for v, f in meshes:
            rs.add(v, f, np.zeros(3))
        rs.commit()
        rng = np.random.default_rng(5)
        tri = np.concatenate([v[f] for v, f in meshes])
        face = rng.integers(0, len(tri), 20_000)
        u = rng.random((len(face), 2))
        s = np.sqrt(u[:, 0])
        b = np.stack([1 - s, s * (1 - u[:, 1]), s * u[:, 1]], axis=1)
        origins = np.einsum("ij,ijk->ik", b, tri[face]).astype(np.float32)
        directions = rng.normal(size=(len(face), 3)).astype(np.float32)
        return {"occluded": rs.occluded(origins, directions).tobytes()}

    return run


# -- enclosed faces (_cenclosure) ------------------------------------------------------------


def enclosure_case(scene):
    def run():
        if scene == "spheres":
            outer, inner = trimesh.creation.icosphere(4), trimesh.creation.icosphere(3, radius=0.5)
            v = np.vstack([outer.vertices, inner.vertices])
            f = np.vstack([outer.faces, inner.faces + len(outer.vertices)]).astype(np.int64)
        else:
            tri = np.concatenate([m.vertices[m.faces] for m in getattr(es, scene)()[0].dump()])
            v, f = tri.reshape(-1, 3).astype(np.float64), np.arange(len(tri) * 3, dtype=np.int64).reshape(-1, 3)
        part, closed = enclosure.closed_parts(v, f)
        offset = float(np.spacing(np.float32(4.0))) * 16
        return {"part": part.tobytes(), "closed": closed.tobytes(),
                "enclosed": enclosure.enclosed_faces(v, f, part, closed, offset).tobytes()}

    return run


# -- volume labels (_cwinding, _cvolume) ------------------------------------------------------


def volume_points(tri, n=3000, seed=5):
    """Points around triangles (T, 3, 3): uniform in the grown box, and some on the corners
    and edge midpoints themselves (where rays and distances tie)."""
    lo, hi = tri.reshape(-1, 3).min(0), tri.reshape(-1, 3).max(0)
    grow = 0.2 * (hi - lo).max()
    box = np.random.default_rng(seed).uniform(lo - grow, hi + grow, (n, 3))
    return np.concatenate([box, tri[:50].reshape(-1, 3), (tri[:50, 0] + tri[:50, 1]) / 2])


def volume_triangles(name):
    if name == "scene":
        from scatter_cli.run.pipeline import plan_surface
        from scatter_cli.volume.source import world_triangles

        return world_triangles(plan_surface(load_surface(SAMPLES / "cesiummilktruck.glb"))[0])[0]
    mesh = load_surface(SAMPLES / name)
    g = mesh.geometries[0]
    return g.vertices[g.faces]


def winding_case(name, **kw):
    def run():
        tri = volume_triangles(name)
        return {"w": winding.winding_numbers(winding.WindingTree(tri), volume_points(tri), **kw).tobytes()}

    return run


def distance_case(name):
    def run():
        tri = volume_triangles(name)
        tree = distance.TriangleTree.from_triangles(tri)
        d, c, f = distance.closest_points(tree, volume_points(tri))
        inside = parity.parity_inside(tree, volume_points(tri), rays=5)
        return {"d": d.tobytes(), "c": c.tobytes(), "f": f.tobytes(), "inside": inside.tobytes()}

    return run


SAMPLING_OPTIONS = [("skull", {}), ("skull", dict(method="stratified")), ("skull", dict(method="sobol")),
                    ("skull", dict(attributes="face,bary,normal", precision="float32")),
                    ("degenerate", dict(attributes="face,bary")), ("instances", dict(attributes="face,object,normal")),
                    ("moved", dict(attributes="normal")), ("truck", dict(attributes="face,object,smooth-normal,color")),
                    ("colors", dict(weight="vertex-color:r")), ("textured", dict(weight="texture:g"))]

CASES = {
    "_csampling": {
        **{f"sample-{n}-{'-'.join(f'{k}={v}' for k, v in o.items()) or 'plain'}": sampling_case(n, **o)
           for n, o in SAMPLING_OPTIONS},
        **{f"face-order-{n}": face_order_case(n) for n in ("skull", "degenerate", "instances", "moved")},
        **{f"normals-{seed}-{c}": normals_case(seed, center) for seed, c, center in
           [(0, "none", None), (1, "none", None), (2, "none", None), (0, "far", [0.3, -1e150, 7.0]),
            (1, "vertex", [1.0, 1.0, 1.0])]},
        **{f"stream-{seed}-{start}": stream_case(seed, start)
           for seed, start in [(0, 0), (7, 3), (2**63 + 5, 10**12), (123456789, 2**40 + 1)]},
    },
    "_cthinning": {
        **{f"thin-{n}": thinning_case(n) for n in point_sets()},
        "thin-line-plain-loops": plain_loops_case("line"),
        **{f"pairs-{n}": pairs_case(n) for n in ("sphere", "clustered", "far")},
        "sample-poisson": lambda: sample_bytes("koala", seed=3, attributes="face", poisson=True, count=3000),
        "sample-radius": lambda: sample_bytes("koala", seed=3, attributes="face", radius=0.04),
    },
    "_cstable": {
        "truck": stable_case("cesiummilktruck.glb", count=5000),
        "pediment-radius": stable_case("pediment_join_plate_12.stl", count=None, radius=1.5),
        "textured-weight": stable_case("boxtextured.glb", count=5000, weight="texture:g"),
    },
    "_creaders": {
        **{f"{fmt}-{mesh}": reader_case(fmt, mesh) for fmt in ("obj", "off", "ply-ascii", "stl-ascii")
           for mesh in ("spot_triangulated.obj", "hemisphere.off")},
        "obj-smooth": reader_case("obj", "spot_triangulated.obj", smooth=True),
    },
    "_cenclosure": {s: enclosure_case(s) for s in ("box_in_box", "double_shell", "car", "cup", "spheres")},
    "_cembree": {s: rays_case(s) for s in ("box_in_box", "car", "cup")},
    "_cwinding": {
        **{f"winding-{n}": winding_case(n) for n in ("icosahedron_binary.stl", "hemisphere.off", "scene")},
        "winding-order-1": winding_case("moebius-160-10.ply", order=1, accuracy=3.0),
        "sample-volume": lambda: sample_bytes("hemisphere", volume=True, count=2000, attributes="winding,inside"),
    },
    "_cedges": {
        "edges-pediment": lambda: sample_bytes("pediment", count=3000, edges=0.5, attributes="normal,face,sharp"),
        "edges-truck": lambda: sample_bytes("truck", count=2000, edges="0.3", sharp_angle=30,
                                            attributes="object,bary,sharp"),
        "edges-near": lambda: sample_bytes("hemisphere", near=(0.02,), near_edges=(0.005,), edges=0.4, count=2000,
                                           attributes="sdf,sharp"),
    },
    "_cvolume": {
        **{f"distance-{n}": distance_case(n) for n in ("icosahedron_binary.stl", "narrow_triangles.obj", "scene")},
        "sample-near": lambda: sample_bytes("hemisphere", near=(0.02,), count=2000, sign="parity",
                                            attributes="sdf,inside,closest,face"),
    },
}


# For every function each kernel exports, a case that must call it (small ones: these cases
# run in the fast loop, pytest -m "not slow", and all the others are marked slow).
CALLED_BY = {
    "_csampling": {"areas": "sample-skull-plain", "bounds": "sample-skull-plain", "draw": "sample-skull-plain",
                   "guide": "sample-skull-plain",
                   "place": "sample-skull-method=stratified", "select": "sample-skull-method=stratified",
                   "unit_normals": "normals-0-none"},
    "_cthinning": {"grid": "pairs-far", "pairs": "pairs-far", "greedy": "thin-line",
                   "use_avx512": "thin-line-plain-loops"},
    "_cstable": {"faces": "truck", "arrivals": "truck", "order": "truck", "place": "pediment-radius"},
    "_creaders": {"read_obj": "obj-hemisphere.off", "read_off": "off-hemisphere.off",
                  "read_ply_ascii": "ply-ascii-hemisphere.off", "read_stl_ascii": "stl-ascii-hemisphere.off"},
    "_cenclosure": {"parts": "box_in_box", "enclosed": "box_in_box"},
    "_cembree": {f: "box_in_box" for f in ("load", "new_scene", "add", "buffers", "commit", "occluded")},
    "_cwinding": {f: "winding-icosahedron_binary.stl" for f in ("morton", "order", "subtree_sums", "moments",
                                                                "expansions", "radii", "winding", "layout",
                                                                "faces")},
    "_cvolume": {f: "distance-icosahedron_binary.stl" for f in ("wide", "order", "thin", "boxes", "visit", "closest",
                                                                "crossings")},
    "_cedges": {"edges": "edges-pediment"},
}


def run_case(run, tmp_path):
    return run(tmp_path) if run.__code__.co_argcount else run()


def holding(kernel):
    """The modules that hold ``kernel``, from the registry."""
    return [importlib.import_module(name) for name in native.holders(kernel)]


def compiled_module(kernel):
    """The built kernel, or None."""
    return native.kernel(kernel) if all(m._kernel is not None for m in holding(kernel)) else None


def functions_of(module):
    return {name for name in dir(module) if not name.startswith("_") and callable(getattr(module, name))}


def watch(module, monkeypatch):
    """Record the name of each function of the compiled ``module`` called from now on."""
    called = set()

    def watched(name, function):
        def call(*args, **kwargs):
            called.add(name)
            return function(*args, **kwargs)

        return call

    for name in functions_of(module):
        monkeypatch.setattr(module, name, watched(name, getattr(module, name)))
    return called


def need_kernel(kernel):
    module = compiled_module(kernel)
    if module is None:
        if REQUIRED:
            pytest.fail(f"{kernel} is not built")
        pytest.skip(f"{kernel} is not built (SCATTER_REQUIRE_KERNELS=1 makes this a failure)")
    return module


def test_every_kernel_has_cases():
    assert set(CASES) == set(CALLED_BY) == set(native.KERNELS)


def uncompared(kernel, table):
    """The functions of ``kernel`` with no case in ``table`` that must call them, and the
    cases ``table`` names that do not exist."""
    listed = table[kernel]
    return (functions_of(need_kernel(kernel)) ^ set(listed)) | {c for c in listed.values() if c not in CASES[kernel]}


@pytest.mark.parametrize("kernel", sorted(native.KERNELS))
def test_every_function_of_every_kernel_is_compared(kernel):
    assert not uncompared(kernel, CALLED_BY)


def test_a_function_left_out_of_the_table_is_reported():
    table = {"_csampling": {f: c for f, c in CALLED_BY["_csampling"].items() if f != "guide"}}
    assert uncompared("_csampling", table) == {"guide"}
    table = {"_csampling": CALLED_BY["_csampling"] | {"unit_normals": "no-such-case"}}
    assert uncompared("_csampling", table) == {"no-such-case"}


def every_case():
    """Every (kernel, case), slow but for the cases CALLED_BY names."""
    named = {(k, c) for k, table in CALLED_BY.items() for c in table.values()}
    return [pytest.param(k, c, marks=() if (k, c) in named else pytest.mark.slow) for k in CASES for c in CASES[k]]


@pytest.mark.parametrize("kernel,case", every_case())
def test_kernel_gives_its_numpy_twin_s_bytes(kernel, case, tmp_path, monkeypatch):
    called = watch(need_kernel(kernel), monkeypatch)
    run = CASES[kernel][case]
    with np.errstate(all="ignore"):
        compiled = run_case(run, tmp_path / "kernel")
        reached = set(called)
        called.clear()
        with monkeypatch.context() as m:
            for module in holding(kernel):
                m.setattr(module, "_kernel", None)
            twin = run_case(run, tmp_path / "numpy")
    assert not called, f"the NumPy run called {sorted(called)}: a module holds {kernel} outside native.KERNELS"
    missed = {f for f, c in CALLED_BY[kernel].items() if c == case} - reached
    assert not missed, f"{case} did not reach {sorted(missed)}"
    assert compiled.keys() == twin.keys()
    for key in compiled:
        assert compiled[key] == twin[key], key


class _OneUlpOff:
    """The sampling kernel with the first point of every draw one ulp off: a broken kernel."""

    def __init__(self, kernel):
        self._kernel = kernel

    def __getattr__(self, name):
        return getattr(self._kernel, name)

    def draw(self, *args):
        out = self._kernel.draw(*args)
        points = args[-3]  # draw(cdf, guide, state, *corner table, used, points, bary, in_face_order)
        points[:1] = np.nextafter(points[:1], np.inf)
        return out


def test_a_kernel_one_ulp_off_fails_the_comparison(tmp_path, monkeypatch):
    need_kernel("_csampling")
    monkeypatch.setattr(sampling, "_kernel", _OneUlpOff(sampling._kernel))
    with pytest.raises(AssertionError, match="points"):
        test_kernel_gives_its_numpy_twin_s_bytes("_csampling", "sample-skull-plain", tmp_path, monkeypatch)


@pytest.mark.parametrize("kernel,left_out,case", [("_cstable", "faces", "truck"),
                                                  ("_cvolume", "parity", "distance-icosahedron_binary.stl"),
                                                  ("_csampling", "normals", "sample-instances-attributes=face,object,normal")])
def test_a_holder_left_out_of_the_registry_fails_the_comparison(kernel, left_out, case, tmp_path, monkeypatch):
    """The NumPy run of a registry without ``left_out`` still calls the kernel there."""
    need_kernel(kernel)
    package, modules = native.KERNELS[kernel]
    monkeypatch.setitem(native.KERNELS, kernel, native.Kernel(package, tuple(m for m in modules if m != left_out)))
    with pytest.raises(AssertionError, match="outside native.KERNELS"):
        test_kernel_gives_its_numpy_twin_s_bytes(kernel, case, tmp_path, monkeypatch)


def test_a_case_that_does_not_reach_its_function_fails(tmp_path, monkeypatch):
    need_kernel("_csampling")
    monkeypatch.setitem(CALLED_BY, "_csampling", CALLED_BY["_csampling"] | {"draw": "normals-0-none"})
    with pytest.raises(AssertionError, match="did not reach"):
        test_kernel_gives_its_numpy_twin_s_bytes("_csampling", "normals-0-none", tmp_path, monkeypatch)
