"""The compiled kernels are built, share the NumPy path's constants, are switched off by
SCATTER_NUMPY=1, take their choices from Python (threads, AVX-512) without changing a
result, and refuse bad arrays. Their parity with the NumPy twins is
tests/test_kernel_parity.py."""

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
from scatter_cli.loading import fast as readers
from scatter_cli.sampling import normals, plan as sampling
from scatter_cli.sampling.exterior import enclosure, rayscene
from scatter_cli.sampling.poisson import pairs
from scatter_cli.sampling.stable import source as stable
from scatter_cli.volume import distance, parity, winding
print(sum(m._kernel is not None for m in (enclosure, pairs, rayscene, readers, sampling, stable, normals,
                                         winding, distance, parity)))
"""


@pytest.mark.parametrize("switch,held", [("1", 0), ("", 10)])
def test_every_module_looks_its_kernel_up_once_through_native(switch, held):
    """Each module holds its kernel from its import: SCATTER_NUMPY=1 leaves every one None
    (the paired case: unset, every one is there)."""
    proc = run_user([sys.executable, "-c", _HELD], cwd=REPO, env={"SCATTER_NUMPY": switch}, check=True)
    assert int(proc.stdout) == held
    for path in (REPO / "scatter_cli").rglob("*.py"):
        text = path.read_text()
        assert not re.search(r"import\s+_c\w+|import_module\(.*_c", text) or path.name == "native.py", path.name
        assert "kernel(" not in text.replace("native.kernel(", "").replace("def kernel(", ""), path.name


def test_no_compiled_file_reads_the_environment_and_all_share_the_checks():
    """The environment is read in Python (native.py) only; every C file that takes arrays
    checks them with _ckernel.h (_creaders takes only bytes and numbers)."""
    for path in sorted((REPO / "scatter_cli").rglob("_c*.c")):
        text = path.read_text()
        assert "getenv" not in text, path.name
        takes_arrays = "PyArray_DATA" in text
        assert ('#include "_ckernel.h"' in text) == takes_arrays, path.name
        assert "PyArray_IS_C_CONTIGUOUS" not in text, path.name  # the checks are get() and get_rows()


def test_the_avx512_choice_is_passed_from_python():
    assert pairs._kernel.use_avx512(False) is False  # off when asked, whatever the CPU
    assert pairs._kernel.use_avx512(True) in (True, False)  # on only where the CPU has it
    native.kernel("_cthinning")  # back to the environment's choice


def test_large_meshes_go_in_face_order_and_larger_chunks():
    small = sampling.SamplePlan(load_surface(trimesh.creation.icosphere(subdivisions=3)))
    large = sampling.SamplePlan(load_surface(trimesh.creation.icosphere(subdivisions=7)))  # 327,680 faces
    assert not small.in_face_order and small.default_chunk == sampling.DEFAULT_CHUNK
    assert large.in_face_order and large.default_chunk == sampling.LARGE_MESH_CHUNK


@pytest.mark.parametrize("threads", ["1", "2", "5"])
def test_greedy_does_not_depend_on_the_thread_count(threads, monkeypatch):
    # enough points for the kernel to split the crowding pass (16,384 a thread at least)
    points = np.random.default_rng(5).normal(size=(90_000, 3))
    points /= np.linalg.norm(points, axis=1, keepdims=True)
    radius = 0.02
    monkeypatch.setenv("SCATTER_THREADS", "1")
    want = thinning.thin_by_radius(points, radius)
    monkeypatch.setenv("SCATTER_THREADS", threads)
    np.testing.assert_array_equal(thinning.thin_by_radius(points, radius), want)


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
