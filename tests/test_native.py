"""The compiled kernels are built, share the NumPy path's constants, are switched off by
SCATTER_NUMPY=1, take their choices from Python (threads, AVX-512) without changing a
result, and refuse bad arrays; the registry (native.KERNELS) names every module that
holds one, and docs/development.md's table agrees with it. Their parity with the NumPy
twins is tests/test_kernel_parity.py."""

import ast
import json
import os
import re
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh

from scatter_cli.sampling.poisson import greedy, pairs, thinning
from scatter_cli.core import native
from scatter_cli.sampling import plan as sampling
from scatter_cli.loading.load import load_surface

from .conftest import run_user

REPO = Path(__file__).resolve().parents[1]
KERNELS_BUILT = sampling._kernel is not None and pairs._kernel is not None
# Without a C compiler the install runs the NumPy path alone and these tests have nothing to
# compare; .ci/run sets SCATTER_REQUIRE_KERNELS=1 so that there a missing kernel fails.
pytestmark = pytest.mark.skipif(
    not KERNELS_BUILT and os.environ.get("SCATTER_REQUIRE_KERNELS", "") in ("", "0"),
    reason="compiled kernels not built (SCATTER_REQUIRE_KERNELS=1 makes this a failure)",
)


def test_the_kernels_are_built():
    # CI must exercise the compiled path: a silent fallback would leave it untested.
    assert KERNELS_BUILT


def test_the_kernels_share_the_numpy_paths_constants():
    # what the C code and the NumPy path must agree on, read from both sides
    assert sampling._kernel.DRAWS_PER_POINT == sampling.DRAWS_PER_POINT
    assert pairs._kernel.BITS == pairs.BITS
    assert pairs._kernel.MAX_CELLS == pairs.MAX_CELLS
    assert pairs._kernel.CROWD_SCALE == greedy.CROWD_SCALE


def test_scatter_numpy_switches_them_off(monkeypatch):
    monkeypatch.setenv("SCATTER_NUMPY", "1")
    assert all(native.kernel(k) is None for k in native.KERNELS)
    monkeypatch.setenv("SCATTER_NUMPY", "0")
    assert all(native.kernel(k) is not None for k in native.KERNELS)


_HELD = """
import importlib, json
from scatter_cli.core import native
print(json.dumps({m: importlib.import_module(m)._kernel is not None for k in native.KERNELS for m in native.holders(k)}))
"""


@pytest.mark.slow
@pytest.mark.parametrize("switch,held", [("1", False), ("", True)])
def test_scatter_numpy_empties_every_holder_in_the_registry(switch, held):
    """SCATTER_NUMPY=1 leaves every module that native.KERNELS says holds a kernel holding
    None (the paired case: unset, every one holds its kernel)."""
    proc = run_user([sys.executable, "-c", _HELD], cwd=REPO, env={"SCATTER_NUMPY": switch}, check=True)
    got = json.loads(proc.stdout)
    assert sorted(got) == sorted(m for k in native.KERNELS for m in native.holders(k))
    assert set(got.values()) == {held}


def _is_lookup(node):
    """Whether ``node`` is a call ``native.kernel(...)``."""
    f = node.func if isinstance(node, ast.Call) else None
    return isinstance(f, ast.Attribute) and f.attr == "kernel" and isinstance(f.value, ast.Name) and f.value.id == "native"


def kernel_lookups(root, package="scatter_cli"):
    """({kernel: {module}}, [(module, line) wrong]) for the package at ``root``: each module
    that holds a kernel as ``_kernel = native.kernel("name")`` at its top level, and the
    lines that look a kernel up or set ``_kernel`` any other way."""
    found, wrong = {}, []
    for path in sorted(root.rglob("*.py")):
        if path.name == "native.py":
            continue
        name = ".".join((package, *path.relative_to(root).with_suffix("").parts))
        tree = ast.parse(path.read_text())
        held = set()
        for node in tree.body:
            value = node.value if isinstance(node, ast.Assign) else None
            if [getattr(t, "id", None) for t in getattr(node, "targets", [])] == ["_kernel"]:
                if _is_lookup(value) and len(value.args) == 1 and isinstance(value.args[0], ast.Constant):
                    found.setdefault(value.args[0].value, set()).add(name)
                    held.add(value)
                else:
                    wrong.append((name, node.lineno))
        wrong += [(name, node.lineno) for node in ast.walk(tree) if _is_lookup(node) and node not in held]
    return found, wrong


def registry_gaps(found, kernels):
    """The (kernel, module) pairs that ``found`` and the registry ``kernels`` do not share."""
    listed = {(k, f"{entry.package}.{m}") for k, entry in kernels.items() for m in entry.holders}
    return sorted(listed ^ {(k, m) for k, modules in found.items() for m in modules})


@pytest.mark.slow
def test_the_registry_names_every_module_that_holds_a_kernel():
    """Every module that looks a kernel up is listed under it in native.KERNELS and every
    listed module looks it up, once, at import, through native.kernel()."""
    found, wrong = kernel_lookups(REPO / "scatter_cli")
    assert not wrong
    assert not registry_gaps(found, native.KERNELS)
    for path in (REPO / "scatter_cli").rglob("*.py"):
        assert not re.search(r"import\s+_c\w+|import_module\(.*_c", path.read_text()) or path.name == "native.py", path


def test_a_holder_the_registry_leaves_out_is_reported(tmp_path):
    (tmp_path / "a.py").write_text('from .core import native\n_kernel = native.kernel("_cx")\n')
    (tmp_path / "b.py").write_text("from . import a\n_kernel = a._kernel\n")  # held outside native
    (tmp_path / "c.py").write_text('def f():\n    return native.kernel("_cx")\n')  # not at import
    (tmp_path / "d.py").write_text('_kernel = native.kernel("_cx")\n')
    found, wrong = kernel_lookups(tmp_path, "p")
    assert found == {"_cx": {"p.a", "p.d"}} and wrong == [("p.b", 2), ("p.c", 2)]
    registry = {"_cx": native.Kernel("p", ("a", "e"))}
    assert registry_gaps(found, registry) == [("_cx", "p.d"), ("_cx", "p.e")]


def test_no_compiled_file_reads_the_environment_and_all_share_the_checks():
    """The environment is read in Python (native.py) only; every C file that takes arrays
    checks them with _ckernel.h (_creaders takes only bytes and numbers)."""
    for path in sorted((REPO / "scatter_cli").rglob("_c*.c")):
        text = path.read_text()
        assert "getenv" not in text, path.name
        takes_arrays = "PyArray_DATA" in text
        assert ('#include "_ckernel.h"' in text) == takes_arrays, path.name
        assert "PyArray_IS_C_CONTIGUOUS" not in text, path.name  # the checks are get() and get_rows()


def own_threads(files):
    """The C files (name -> text) other than _cthreads.h that start threads or cap them
    themselves (the header's in_parallel and MAX_THREADS are the only ones)."""
    return sorted(name for name, text in files.items()
                  if name != "_cthreads.h" and re.search(r"pthread_create|pthread\.h|#\s*define\s+MAX_THREADS", text))


def test_every_kernel_starts_its_threads_through_cthreads_h():
    files = {p.name: p.read_text() for p in (REPO / "scatter_cli").rglob("_c*.[ch]")}
    assert "_cthreads.h" in files and not own_threads(files)
    hand_made = "static void *run(void *a) { return a; }\nvoid go(pthread_t *t) { pthread_create(t, 0, run, 0); }"
    assert own_threads(files | {"_cnew.c": hand_made, "_cold.c": "#define MAX_THREADS 8"}) == ["_cnew.c", "_cold.c"]


def test_the_avx512_choice_is_passed_from_python():
    assert pairs._kernel.use_avx512(False) is False  # off when asked, whatever the CPU
    assert pairs._kernel.use_avx512(True) in (True, False)  # on only where the CPU has it
    native.kernel("_cthinning")  # back to the environment's choice


def test_large_meshes_go_in_face_order_and_larger_chunks():
    small = sampling.SamplePlan(load_surface(trimesh.creation.icosphere(subdivisions=3)))
    large = sampling.SamplePlan(load_surface(trimesh.creation.icosphere(subdivisions=7)))  # 327,680 faces
    assert not small.in_face_order and small.default_chunk == sampling.DEFAULT_CHUNK
    assert large.in_face_order and large.default_chunk == sampling.LARGE_MESH_CHUNK


_THIN_IN_A_CHILD = """
import sys
import numpy as np
from scatter_cli.sampling.poisson import pairs, thinning
from tests.test_kernel_parity import point_sets
out = {}
for name in ("sphere", "clustered", "wall"):
    points, radius = point_sets()[name]
    out[name + "-radius"] = thinning.thin_by_radius(points, radius)
    out[name + "-count"] = thinning.thin_to_count(points, 500, 1.0)[0]
    i, j, d = pairs.all_pairs(points, radius)
    key = np.lexsort((j, i))
    out[name + "-pairs"] = np.stack([i[key], j[key], d[key].view(np.int64)])
np.savez(sys.argv[1], **out)
"""


@pytest.mark.slow
def test_the_avx512_loops_keep_the_same_points(tmp_path):
    """With and without the AVX-512 distance loops (SCATTER_NO_AVX512=1) the kernel finds
    the same pairs and keeps the same points. (On a CPU without AVX-512 both runs take
    the plain loops.)"""
    runs = []
    for plain in ("", "1"):
        out = tmp_path / f"plain{plain}.npz"
        env = {"SCATTER_NO_AVX512": plain}  # empty means unset
        run_user([sys.executable, "-c", _THIN_IN_A_CHILD, str(out)], cwd=REPO, env=env, check=True)
        runs.append(np.load(out))
    assert set(runs[0].files) == set(runs[1].files)
    for key in runs[0].files:
        np.testing.assert_array_equal(runs[0][key], runs[1][key], err_msg=key)


def test_kernels_refuse_bad_arrays_instead_of_crashing():
    k = sampling._kernel
    out = np.empty(1)
    with pytest.raises(ValueError, match="out of range"):
        k.areas(np.zeros((3, 3)), np.array([[0, 1, 3]]), None, out)
    with pytest.raises(TypeError):
        k.areas(np.zeros((3, 3), dtype=np.float32), np.array([[0, 1, 2]]), None, out)
    with pytest.raises(TypeError):
        pairs._kernel.grid(np.zeros((4, 2)), np.zeros(3), 1.0, 0)


def kernel_table_errors(text, kernels):
    """The rows of the kernel table in ``text`` (docs/development.md) that disagree with
    the registry ``kernels`` on the C file or the modules holding it, and the kernels it lacks."""
    rows = {}
    for line in text.splitlines():
        cells = [c.strip().replace("`", "") for c in line.strip("| ").split("|")]
        if line.startswith("| `_c") and len(cells) == 4:
            rows[cells[0]] = (cells[1], cells[2])
    errors = sorted(set(kernels) ^ set(rows))
    for name in set(kernels) & set(rows):
        c_file = "/".join([*kernels[name].package.split(".")[1:], name + ".c"])
        want = (c_file, ", ".join(h.removeprefix("scatter_cli.") for h in native.holders(name)))
        if rows[name] != want:
            errors.append(name)
    return errors


def test_the_development_guide_lists_every_kernel():
    assert not kernel_table_errors((REPO / "docs" / "development.md").read_text(), native.KERNELS)
    for path in REPO.glob("scatter_cli/**/_c*.c"):  # and every C file is a kernel of the registry
        assert native.KERNELS[path.stem].package == ".".join(path.parent.relative_to(REPO).parts)


def test_a_kernel_missing_from_the_table_is_reported():
    text = (REPO / "docs" / "development.md").read_text()
    no_row = "\n".join(line for line in text.splitlines() if not line.startswith("| `_cstable`"))
    assert kernel_table_errors(no_row, native.KERNELS) == ["_cstable"]
    moved = text.replace("`volume.distance`, `volume.parity`", "`volume.distance`")
    assert kernel_table_errors(moved, native.KERNELS) == ["_cvolume"]


def cgroup_tree(tmp_path, membership, files):
    """A fake /sys/fs/cgroup under tmp_path with ``files`` {path: text}, and a fake
    /proc/self/cgroup holding ``membership``: (root, membership file)."""
    for path, text in files.items():
        (tmp_path / path).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / path).write_text(text)
    (tmp_path / "self-cgroup").write_text(membership)
    return str(tmp_path / "fs"), str(tmp_path / "self-cgroup")


@pytest.mark.parametrize("membership, files, want", [
    # cgroup v2: the least quota of the process's cgroup and those above it
    ("0::/job/step\n", {"fs/job/step/cpu.max": "max 100000\n", "fs/job/cpu.max": "150000 100000\n",
                        "fs/cpu.max": "400000 100000\n"}, 1.5),
    # v1, the cpu controller mounted with cpuacct
    ("4:memory:/x\n1:cpu,cpuacct:/job\n", {"fs/cpu,cpuacct/job/cpu.cfs_quota_us": "250000\n",
                                           "fs/cpu,cpuacct/job/cpu.cfs_period_us": "100000\n"}, 2.5),
    # a container: its own cgroup mounted as the root, the membership path not visible
    ("0::/docker/abc\n", {"fs/cpu.max": "300000 100000\n"}, 3.0),
    ("0::/\n", {"fs/cpu.max": "max 100000\n"}, None),  # no quota
    ("1:cpu,cpuacct:/\n", {"fs/cpu,cpuacct/cpu.cfs_quota_us": "-1\n", "fs/cpu,cpuacct/cpu.cfs_period_us": "100000\n"}, None),
])
def test_the_cgroup_cpu_quota_is_read(tmp_path, membership, files, want):
    assert native.cgroup_cpu_quota(*cgroup_tree(tmp_path, membership, files)) == want


def test_the_default_threads_are_the_cpus_this_process_may_use(monkeypatch):
    """The affinity mask, at most the quota rounded up; SCATTER_THREADS overrides it. The
    broken variants: a quota ignored, a fixed cap."""
    monkeypatch.delenv("SCATTER_THREADS", raising=False)
    monkeypatch.setattr(native.os, "sched_getaffinity", lambda pid: set(range(64)))

    def default(quota):
        monkeypatch.setattr(native, "cgroup_cpu_quota", lambda: quota)
        native.available_cpus.cache_clear()
        native._threads.cache_clear()
        return native.worker_count()

    try:
        assert [default(None), default(2.5), default(100.0), default(0.2)] == [64, 3, 64, 1]
        monkeypatch.setenv("SCATTER_THREADS", "5")
        assert default(2.5) == 5
    finally:
        native.available_cpus.cache_clear()
        native._threads.cache_clear()


def test_a_quota_above_the_process_cgroup_counts(tmp_path, monkeypatch):
    """The broken variant reads the process's own cgroup alone: a job's quota set on the
    cgroup above its step goes unseen."""
    args = cgroup_tree(tmp_path, "0::/job/step\n", {"fs/job/step/cpu.max": "max 100000\n",
                                                   "fs/job/cpu.max": "150000 100000\n"})
    assert native.cgroup_cpu_quota(*args) == 1.5
    levels = native._levels
    monkeypatch.setattr(native, "_levels", lambda folder, path: levels(folder, path)[:1])
    assert native.cgroup_cpu_quota(*args) is None
