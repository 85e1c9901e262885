"""The same bytes whatever the thread count, on every kernel and every kind of run.

Each kernel of native.KERNELS has a case here large enough for its work to be cut into
pieces (above every kernel's one-thread threshold), run on 1 thread and then on 2, 3,
7, 16 and 64 (more threads than this machine's cores: the oversubscribed runs that a
2-core machine can still make), every result compared byte for byte. A case must reach
its kernel with the thread count asked for (a kernel that never sees more than one
thread would pass vacuously), and a kernel whose result moved with the thread count
fails the comparison (the broken variant).
"""

import contextlib
import functools
import threading
import time

import numpy as np
import pytest
import trimesh

import scatter_cli
from scatter_cli.core import native
from scatter_cli.loading import fast
from scatter_cli.sampling import plan, sharp
from scatter_cli.sampling.exterior import enclosure
from scatter_cli.sampling.normals import face_normals
from scatter_cli.sampling.poisson import pairs, thinning
from scatter_cli.volume import distance, parity, winding

from .conftest import SAMPLES

THREADS = ("2", "3", "7", "16", "64")
pytestmark = pytest.mark.skipif(any(native.kernel(k) is None for k in native.KERNELS),
                                reason="compiled kernels not built")


@functools.lru_cache(maxsize=None)  # the inputs are made once; only the runs repeat
def skull():
    mesh = trimesh.load(SAMPLES / "skull.ply", process=False)
    return np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64)


def run_bytes(**options):
    """Every array of a run of the skull, as bytes."""
    s = scatter_cli.sample(str(SAMPLES / "skull.ply"), **options)
    return {"points": s.points.tobytes()} | {k: v.tobytes() for k, v in s.attributes.items()}


def sampling_case():
    # 100k faces (areas and the guide table in blocks) and chunks of 8192 points in pieces
    return run_bytes(count=100_003, seed=3, chunk_size=8192, attributes="face,bary,normal")


@functools.lru_cache(maxsize=None)
def sphere_points(n=50_000):
    points = np.random.default_rng(5).normal(size=(n, 3))
    return points / np.linalg.norm(points, axis=1, keepdims=True)


def thinning_case():
    points = sphere_points()  # several pieces of the crowding pass
    by_radius = thinning.thin_by_radius(points, 0.03)
    by_count, d_min = thinning.thin_to_count(points, 3000, 4 * np.pi)
    return {"by_radius": by_radius.tobytes(), "by_count": by_count.tobytes(), "d_min": d_min}


def stable_case():
    return run_bytes(count=150_000, stable=True, attributes="face,bary")


@functools.lru_cache(maxsize=None)
def two_shells():
    outer, inner = trimesh.creation.icosphere(6), trimesh.creation.icosphere(3, radius=0.4)  # 81,920 faces outside
    v = np.vstack([outer.vertices, inner.vertices])
    return v, np.vstack([outer.faces, inner.faces + len(outer.vertices)]).astype(np.int64)


def enclosure_case():
    v, f = two_shells()
    part, closed = enclosure.closed_parts(v, f)
    enclosed = enclosure.enclosed_faces(v, f, part, closed, float(np.spacing(np.float32(4.0))) * 16)
    assert enclosed[-1280:].all()  # (the case certifies something: the inner shell)
    return {"part": part.tobytes(), "closed": closed.tobytes(), "enclosed": enclosed.tobytes()}


def rays_case():
    return run_bytes(count=8_000, exterior=True, attributes="face")


FACET = "facet normal 0 0 1\n outer loop\n" + "  vertex %.9g %.9g %.9g\n" * 3 + " endloop\nendfacet\n"


@functools.lru_cache(maxsize=None)
def ascii_stl():
    v, f = skull()
    corners = v[f[:16_000]]  # 4 MB of text: parts of 1 MB
    return ("solid skull\n" + FACET * len(corners) % tuple(corners.ravel()) + "endsolid skull\n").encode()


@functools.lru_cache(maxsize=None)
def text_meshes():
    """The skull's vertices and 40,000 of its faces as an OFF, an ASCII PLY and an OBJ
    (2.4 MB each: two parts)."""
    v, f = skull()
    f = f[:40_000]
    vertices = "".join("%.9g %.9g %.9g\n" % tuple(r) for r in v.tolist())
    body = vertices + "".join("3 %d %d %d\n" % tuple(r) for r in f.tolist())
    header = (f"ply\nformat ascii 1.0\nelement vertex {len(v)}\nproperty double x\nproperty double y\n"
              f"property double z\nelement face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n")
    obj = "".join("v " + line for line in vertices.splitlines(True)) + "".join(
        ("usemtl m%d\n" % (k // 9000) if k % 9000 == 0 else "") + "f %d %d %d\n" % tuple(x + 1 for x in r)
        for k, r in enumerate(f.tolist()))
    return {"off": f"OFF\n{len(v)} {len(f)} 0\n{body}".encode(), "ply": (header + body).encode(), "obj": obj.encode()}


def readers_case():
    got = {"corners": fast.read_stl(ascii_stl(), "skull.stl", False, False, False)[0][0].tobytes()}
    for name, data in text_meshes().items():
        read = {"off": fast.read_off, "ply": fast.read_ply, "obj": fast.read_obj}[name]
        got[name] = b"".join(v.tobytes() + f.tobytes() for v, f in read(data, "skull." + name, False, False, False))
    return got


@functools.lru_cache(maxsize=None)
def volume_points(n=10_000):
    v, f = skull()
    lo, hi = v.min(0), v.max(0)
    points = np.random.default_rng(2).uniform(lo - 0.1 * (hi - lo), hi + 0.1 * (hi - lo), (n, 3))
    return distance.TriangleTree.from_triangles(v[f]), winding.WindingTree(v[f]), points


def winding_case():
    _, tree, points = volume_points()
    return {"w": winding.winding_numbers(tree, points).tobytes()}


def volume_case():
    tree, _, points = volume_points()
    d, c, f = distance.closest_points(tree, points)
    inside = parity.parity_inside(tree, points, rays=5)
    return {"d": d.tobytes(), "c": c.tobytes(), "f": f.tobytes(), "inside": inside.tobytes()}


def edges_case():
    v, f = skull()
    normals = face_normals(v, f)
    got = sharp.edge_slots(v, f, np.any(normals != 0, axis=1), normals, 0.99)
    return {k: getattr(got, k).tobytes() for k in ("head", "second", "count", "rest")}


# kernel -> (case, (module holding it, its function given the thread count, where in its arguments))
CASES = {
    "_csampling": (sampling_case, None),
    "_cthinning": (thinning_case, (pairs, "greedy", -1)),
    "_cstable": (stable_case, None),
    "_cenclosure": (enclosure_case, (enclosure, "enclosed", -2)),
    "_cembree": (rays_case, None),
    "_creaders": (readers_case, (fast, "read_stl_ascii", 1)),
    "_cwinding": (winding_case, (winding, "winding", -2)),
    "_cvolume": (volume_case, (distance, "closest", -2)),
    "_cedges": (edges_case, (sharp, "edges", 5)),
}


def test_every_kernel_has_a_case():
    assert set(CASES) == set(native.KERNELS)


class Spy:
    """A kernel module whose function ``name`` records the thread count it is given
    (argument ``at``) and, when ``skew``, flips a byte of its first output array on more
    than one thread: a kernel whose result depends on the thread count."""

    def __init__(self, kernel, name, at, skew=False):
        self._kernel, self._name, self._at, self._skew, self.threads = kernel, name, at, skew, []

    def __getattr__(self, attr):
        if attr != self._name:
            return getattr(self._kernel, attr)

        def call(*args):
            self.threads.append(args[self._at])
            out = getattr(self._kernel, attr)(*args)
            if self._skew and args[self._at] > 1:
                target = next(a for a in reversed(args) if isinstance(a, np.ndarray) and a.flags.writeable)
                target.view(np.uint8)[:1] ^= 1
            return out

        return call


def results(kernel, monkeypatch, threads=("1",) + THREADS, skew=False):
    """{threads: the case's result} and the thread counts its kernel was given."""
    case, watched = CASES[kernel]
    spy = None
    if watched is not None:
        module, name, at = watched
        spy = Spy(module._kernel, name, at, skew)
        monkeypatch.setattr(module, "_kernel", spy)
    out = {}
    for t in threads:
        monkeypatch.setenv("SCATTER_THREADS", t)
        out[t] = case()
    return out, ([] if spy is None else spy.threads)


def differing(out):
    """The thread counts whose result differs from the one thread's, and in what."""
    return {t: sorted(k for k in out["1"] if out[t][k] != out["1"][k]) for t in out if out[t] != out["1"]}


@pytest.mark.slow
@pytest.mark.parametrize("kernel", sorted(CASES))
def test_every_kernel_gives_the_same_bytes_on_any_thread_count(kernel, monkeypatch):
    out, given = results(kernel, monkeypatch)
    assert not differing(out)
    if CASES[kernel][1] is not None:
        assert max(given) == 64, f"{kernel} never got 64 threads: {sorted(set(given))}"


def test_a_kernel_whose_result_moves_with_the_threads_is_caught(monkeypatch):
    out, given = results("_cvolume", monkeypatch, threads=("1", "7"), skew=True)
    assert differing(out) == {"7": ["f"]} and set(given) == {1, 7}


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["surface", "poisson", "stable", "exterior", "volume", "edges"])
def test_every_kind_of_run_gives_the_same_bytes_on_any_thread_count(kind, monkeypatch):
    """Whole runs through the API: the chunk pool, its pieces and the kernels together (on
    1, 3 and 64 threads: the kernels alone are tried on every count above)."""
    options = {"surface": dict(count=100_001, chunk_size=30_000, attributes="normal,face,bary"),
               "poisson": dict(count=5_000, poisson=True, attributes="face"),
               "stable": dict(count=20_000, stable=True, exterior=True),
               "exterior": dict(count=20_000, exterior=True, attributes="face,object"),
               "volume": dict(count=10_000, near=(0.5,), box_share=0.3, chunk_size=4096,
                              attributes="sdf,inside,closest,face"),
               "edges": dict(count=50_000, edges=0.3, attributes="sharp,normal")}[kind]
    out = {}
    for t in ("1", "3", "64"):
        monkeypatch.setenv("SCATTER_THREADS", t)
        out[t] = run_bytes(seed=11, **options)
    assert not differing(out)


def most_points_in_flight(threads, split, n=3_000_000, chunk=1 << 17):
    """The most points that run_chunks had computed or computing, not yet taken, at once."""
    lock, live = threading.Lock(), [0, 0]  # now, most

    def job(a, b):
        with lock:
            live[0] += b - a
            live[1] = max(live[1], live[0])
        time.sleep(0.001)  # (long enough for the pool to fill)
        return b - a

    for taken in plan.run_chunks(job, 0, n, chunk, threads, split):
        with lock:
            live[0] -= taken
    return live[1]


@pytest.mark.parametrize("threads", [2, 7, 64, 256])
def test_the_points_in_flight_do_not_grow_with_the_threads(threads, monkeypatch):
    """Memory per thread bounded: IN_FLIGHT chunks' worth of points at most whatever the
    threads (pieces of chunks), one chunk's for jobs that split their range themselves;
    the broken variant holds two whole chunks a thread."""
    chunk = 1 << 17
    assert most_points_in_flight(threads, True, chunk=chunk) <= plan.IN_FLIGHT * chunk
    assert most_points_in_flight(threads, False, chunk=chunk) <= chunk
    monkeypatch.setattr(plan, "pieces", lambda n, size, threads: (size, 2 * threads))
    assert most_points_in_flight(threads, True, chunk=chunk) > plan.IN_FLIGHT * chunk


def test_one_wide_tree_is_made_whatever_the_threads_that_ask(monkeypatch):
    """The chunk threads of a volume run ask for the kernel's tree at once: it is made
    once (made by each, it was twice the memory); the broken variant has no lock."""
    tree, _, _ = volume_points()

    kernel = distance._kernel

    class Counting:
        made = 0

        def __getattr__(self, name):
            return getattr(kernel, name)

        def wide(self, *args):
            Counting.made += 1
            time.sleep(0.05)  # (every asking thread arrives meanwhile)
            return kernel.wide(*args)

    def made_by(threads):
        Counting.made, tree._wide = 0, None
        with native.thread_pool(threads) as pool:
            list(pool.map(lambda _: tree.wide(), range(threads)))
        return Counting.made

    monkeypatch.setattr(distance, "_kernel", Counting())
    assert made_by(8) == 1
    monkeypatch.setattr(distance.TriangleTree, "_making", contextlib.nullcontext())
    assert made_by(8) > 1
