"""Fuzz the mesh loaders with malformed PLY/OBJ/STL/OFF bytes (hypothesis drives mutations).

Property: any byte string loads and samples, or fails with a ScatterError (one-line error).
The long run (tens of thousands of inputs) is benchmarks/fuzz_loaders.py.
"""

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from testkit.fuzz_inputs import MUTATIONS, SEEDS, differential, exercise, mutate

ops = st.lists(st.tuples(st.integers(0, MUTATIONS - 1), st.integers(0, 1 << 16), st.integers(0, 1 << 16)), min_size=1, max_size=5)


# Each check with the answers it may give: loading never crashes, and the fast readers read
# what trimesh reads or hand the file over to it.
CHECKS = {"load": (exercise, ("ok", "error"), "ok"), "fast-readers": (differential, ("same", "handed"), "same")}


@pytest.mark.slow
@pytest.mark.parametrize("check", sorted(CHECKS))
@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(st.sampled_from(sorted(SEEDS)), ops)
def test_mutated_mesh_bytes(tmp_path, check, name, mutation):
    run, answers, _ = CHECKS[check]
    suffix, seed = SEEDS[name]
    assert run(mutate(seed, mutation), suffix, tmp_path) in answers


@pytest.mark.parametrize("check", sorted(CHECKS))
@pytest.mark.parametrize("name", sorted(SEEDS))
def test_every_seed_is_read(tmp_path, check, name):
    run, _, answer = CHECKS[check]
    suffix, seed = SEEDS[name]
    assert run(seed, suffix, tmp_path) == answer


@pytest.mark.parametrize("data,suffix", [
    (b"v 0 0 0\nv 1 0 0\nv 0 1.8 0\nv 0 0\nf 1 2 3\nf 1 3 4\n", "obj"),  # a 2-coordinate vertex: was a ValueError
    (b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0.01e308 0 1\nf 1 2 3\nf 1 2 4\n", "obj"),  # was float32 inf output
])
def test_fuzz_findings_stay_fixed(tmp_path, data, suffix):
    assert exercise(data, suffix, tmp_path) in ("ok", "error")


@pytest.mark.parametrize("name,tail", [
    ("ply-binary", b"\x00\x01"),  # trailing bytes: trimesh rejects the file, so the fast reader hands it over
    ("ply-ascii", b"3 \n"),  # a stray partial line after the faces: likewise
    ("ply-ascii", b"\n\x8f"),
    ("ply-ascii-quads", b" 1 3 2\n0"),  # a space after the faces once looped for ever (ASan fuzz run)
])
def test_differential_findings_stay_fixed(tmp_path, name, tail):
    suffix, seed = SEEDS[name]
    assert differential(seed + tail, suffix, tmp_path) == "handed"


@pytest.mark.parametrize("count", [b"499999999999999999999", b"9223372036854775808"])
def test_a_vertex_count_past_int64_is_handed_over(tmp_path, count):
    """An ASCII PLY count too large for the compiled reader's int64 argument once raised
    OverflowError (sanitizer fuzz run, seed 0): now the header parse hands it over."""
    suffix, seed = SEEDS["ply-ascii"]
    data = seed.replace(b"element vertex 4", b"element vertex " + count)
    assert differential(data, suffix, tmp_path) == "handed"
    assert exercise(data, suffix, tmp_path) == "error"


@pytest.mark.parametrize("tail", [b" ", b"  \n \n", b"\t\r\n"])
def test_blank_space_after_the_faces_is_read(tmp_path, tail):
    """The ASCII PLY reader's scan of what follows the faces steps over spaces (it once
    stood still on one)."""
    suffix, seed = SEEDS["ply-ascii"]
    assert differential(seed + tail, suffix, tmp_path) == "same"


@pytest.mark.parametrize("name", ["ply-binary", "ply-ascii"])
@pytest.mark.parametrize("blank", [b"\n", b"   \n"])
def test_a_blank_header_line_goes_to_trimesh(tmp_path, name, blank):
    """trimesh's PLY header parser fails on a blank line, so the fast readers must not
    read such a file (a finding of the sanitizer fuzz run, seed 1)."""
    suffix, seed = SEEDS[name]
    assert differential(seed.replace(b"element face", blank + b"element face"), suffix, tmp_path) == "handed"
