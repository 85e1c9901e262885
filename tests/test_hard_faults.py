"""Bad input and faults through the real command (a subprocess): one line, the documented
exit code, no partial output, an existing output untouched, no temporary file left."""

import ctypes
import glob
import os
import resource
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from .conftest import SAMPLES, popen_user, run_scatter, run_user, scatter_command, scatter_in_process
from testkit.fuzz_inputs import SEEDS

pytestmark = pytest.mark.slow  # a subprocess a test

PRECIOUS = b"precious bytes from an earlier run"


def assert_one_line_error(proc, code, *words):
    err = proc.stderr.decode()
    assert proc.returncode == code, (proc.returncode, err)
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    assert "Traceback" not in err
    for w in words:
        assert w in lines[0], (w, lines[0])


def assert_clean(folder, existing=None, new=None):
    """No temporary files in ``folder``; ``existing`` untouched; ``new`` never created."""
    leftovers = [p for p in os.listdir(folder) if p.startswith(".") or p.endswith(".part")]
    assert not leftovers, f"temporary files left behind: {leftovers}"
    if existing is not None:
        assert existing.read_bytes() == PRECIOUS
    if new is not None:
        assert not new.exists(), "a partial output file appeared"


@pytest.fixture
def out(tmp_path):
    """(folder, existing output file, path of an output that must not appear)."""
    folder = tmp_path / "out"
    folder.mkdir()
    existing = folder / "existing.ply"
    existing.write_bytes(PRECIOUS)
    return folder, existing, folder / "new.csv"


def run_both(out, *args, run=run_scatter, **kw):
    """Run the command twice: onto the existing file and onto a new one."""
    folder, existing, new = out
    a = run(*args, "-o", existing, **kw)
    b = run(*args, "-o", new, **kw)
    return a, b


def write_obj(path, vertices, faces):
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in vertices] + [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    path.write_text("\n".join(lines) + "\n")
    return path


GOOD = SAMPLES / "icosahedron_binary.stl"


# ---------------------------------------------------------------- the contract's Errors rows and more input faults


def _inputs(tmp):
    """name -> (path, exit code, words in the message)."""
    cases = {}
    cases["missing"] = (tmp / "nope.ply", 1, ["nope.ply", "no such file"])
    cases["directory"] = (tmp, 1, ["directory"])
    for suffix in ("ply", "obj", "stl", "off", "glb"):
        p = tmp / f"empty.{suffix}"
        p.write_bytes(b"")
        cases[f"empty-{suffix}"] = (p, 1, [p.name, "empty"])
        p = tmp / f"garbage.{suffix}"
        p.write_bytes(np.random.default_rng(len(suffix)).bytes(3000))
        cases[f"garbage-{suffix}"] = (p, 1, [p.name])
    for name, (suffix, data) in SEEDS.items():
        if name != "obj":  # a cut OBJ is a valid smaller OBJ; a cut binary file is detectably short
            p = tmp / f"cut-{name}.{suffix}"
            p.write_bytes(data[: len(data) // 3])
            cases[f"truncated-{name}"] = (p, 1, [p.name])
    for glb in ("boxtextured.glb", "cesiummilktruck.glb"):
        p = tmp / f"cut-{glb}"
        p.write_bytes((SAMPLES / glb).read_bytes()[:2000])
        cases[f"truncated-{glb}"] = (p, 1, [p.name])
    cases["no-faces"] = (write_obj(tmp / "points.obj", [[0, 0, 0], [1, 0, 0]], []), 1, ["points.obj"])
    cases["no-area"] = (write_obj(tmp / "flat.obj", [[0, 0, 0], [1, 1, 1], [2, 2, 2]], [[0, 1, 2], [0, 0, 1]]), 1,
                        ["flat.obj", "area"])
    cases["all-non-finite"] = (write_obj(tmp / "nan.obj", [[np.nan, 0, 0], [1, 0, 0], [0, np.inf, 0]], [[0, 1, 2]]), 1,
                               ["nan.obj", "finite"])
    cases["index-out-of-range"] = (tmp / "oor.ply", 1, ["oor.ply"])
    (tmp / "oor.ply").write_text("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                                 "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
                                 "0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n")
    cases["unknown-suffix"] = (tmp / "mesh.xyz9", 2, ["xyz9"])
    (tmp / "mesh.xyz9").write_text("hello")
    return cases


INPUT_CASES = sorted([  # the keys of _inputs(), listed so that pytest can name them before tmp_path exists
    "missing", "directory", *[f"{k}-{s}" for k in ("empty", "garbage") for s in ("ply", "obj", "stl", "off", "glb")],
    *[f"truncated-{n}" for n in SEEDS if n != "obj"], "truncated-boxtextured.glb", "truncated-cesiummilktruck.glb",
    "no-faces", "no-area", "all-non-finite", "index-out-of-range", "unknown-suffix"])


@pytest.mark.parametrize("case", INPUT_CASES)
def test_bad_input(tmp_path, out, case):
    src = tmp_path / "in"
    src.mkdir()
    path, code, words = _inputs(src)[case]
    # input errors come before the output is opened; the new-file variant of every
    # output fault is tested below (permissions, disk full, signals)
    run = run_scatter if case == "missing" else scatter_in_process  # one in a real process
    assert_one_line_error(run("sample", path, "-n", 10, "-o", out[1]), code, *words)
    assert_clean(out[0], out[1], out[2])


@pytest.mark.parametrize(
    "args,words",
    [
        (["-n", "-5"], ["count"]), (["-n", "1.5"], ["count"]), (["-n", "ten"], ["count"]),
        (["--radius", "0"], ["radius"]), (["--radius", "-1"], ["radius"]), (["--radius", "nan"], ["radius"]),
        (["-a", "normal,sparkle"], ["sparkle"]), (["--density", "0"], ["density"]), (["--density", "inf"], ["density"]),
        (["-f", "e57"], ["e57"]),
    ],
)
def test_bad_values_are_usage_errors(out, args, words):
    run = run_scatter if args == ["-n", "-5"] else scatter_in_process  # one in a real process
    for proc in run_both(out, "sample", GOOD, *args, run=run):
        assert_one_line_error(proc, 2, *words)
    assert_clean(out[0], out[1], out[2])


def test_attribute_the_mesh_cannot_provide(out):
    for proc in run_both(out, "sample", GOOD, "-a", "uv"):
        assert_one_line_error(proc, 1, "uv", GOOD.name)
    assert_clean(out[0], out[1], out[2])


def test_some_non_finite_vertices_warn_and_succeed(tmp_path):
    path = tmp_path / "some.ply"
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [np.nan, 0, 0], [0, np.inf, 0]], dtype="<f4")
    head = ("ply\nformat binary_little_endian 1.0\nelement vertex 5\nproperty float x\nproperty float y\nproperty float z\n"
            "element face 3\nproperty list uchar int vertex_indices\nend_header\n").encode()
    faces = np.array([(3, 0, 1, 2), (3, 0, 1, 3), (3, 1, 4, 2)], dtype=[("n", "u1"), ("a", "<i4"), ("b", "<i4"), ("c", "<i4")])
    path.write_bytes(head + v.tobytes() + faces.tobytes())
    proc = run_scatter("sample", path, "-n", 100, "-a", "face", check=True)
    err = proc.stderr.decode().strip().splitlines()
    assert len(err) == 1 and err[0].startswith("warning: ") and "2 faces" in err[0] and "some.ply" in err[0]
    table = np.loadtxt(proc.stdout.decode().splitlines()[1:], delimiter=",")
    assert (table[:, 3] == 0).all() and np.isfinite(table).all()


# ---------------------------------------------------------------- permissions (root-proof)


def _drop_file_capabilities():
    """preexec_fn: drop CAP_CHOWN, CAP_DAC_OVERRIDE, CAP_DAC_READ_SEARCH and CAP_FOWNER from
    the bounding set, so that even root obeys the mode bits after exec. (Running as nobody
    would not do here: the interpreter lives where nobody cannot read.)"""
    libc = ctypes.CDLL(None, use_errno=True)
    for cap in (0, 1, 2, 3):
        if libc.prctl(24, cap, 0, 0, 0) != 0:  # PR_CAPBSET_DROP
            raise OSError(ctypes.get_errno(), "prctl(PR_CAPBSET_DROP)")


def run_unprivileged(*args):
    cmd = scatter_command(*args)
    if os.geteuid() != 0:
        return run_user(cmd)
    try:
        return run_user(cmd, preexec_fn=_drop_file_capabilities)
    except subprocess.SubprocessError as exc:  # prctl refused (no CAP_SETPCAP in this container)
        pytest.skip(f"cannot drop root's file capabilities here: {exc}")


def test_input_without_read_permission(tmp_path, out):
    path = tmp_path / "secret.stl"
    path.write_bytes(GOOD.read_bytes())
    path.chmod(0)
    folder, existing, new = out
    for target in (existing, new):
        assert_one_line_error(run_unprivileged("sample", path, "-o", target), 1, "secret.stl", "permission denied")
    assert_clean(folder, existing, new)


def test_read_only_output_folder(tmp_path):
    folder = tmp_path / "ro"
    folder.mkdir()
    existing = folder / "existing.ply"
    existing.write_bytes(PRECIOUS)
    folder.chmod(0o555)
    try:
        for target in (existing, folder / "new.ply"):
            assert_one_line_error(run_unprivileged("sample", GOOD, "-o", target), 1, target.name, "ermission denied")
        assert_clean(folder, existing, folder / "new.ply")
    finally:
        folder.chmod(0o755)


def test_output_folder_missing(tmp_path):
    target = tmp_path / "no" / "such" / "out.ply"
    assert_one_line_error(run_scatter("sample", GOOD, "-o", target), 1, "does not exist")
    assert not (tmp_path / "no").exists()


def test_output_is_a_directory(out):
    assert_one_line_error(run_scatter("sample", GOOD, "-f", "ply", "-o", out[0]), 1, "directory")
    assert_clean(out[0], out[1])


# ---------------------------------------------------------------- disk full


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="no /dev/full on this system")
def test_disk_full_device():
    assert_one_line_error(run_scatter("sample", GOOD, "-n", 100000, "-f", "csv", "-o", "/dev/full"), 1,
                          "/dev/full", "No space left")


def test_disk_full_regular_file(out):
    """A file-size limit makes write() fail with EFBIG in the middle of the file, as a full
    disk would with ENOSPC: the temporary file goes, the existing output stays."""
    folder, existing, new = out

    def limit():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (1 << 20, 1 << 20))

    for target in (existing, new):
        proc = run_user(scatter_command("sample", GOOD, "-n", "200000", "-f", "csv", "-o", target), preexec_fn=limit)
        assert_one_line_error(proc, 1, target.name, "cannot write")
    assert_clean(folder, existing, new)


# ---------------------------------------------------------------- closed pipe and signals


def test_closed_standard_output_is_quiet_141():
    """`scatter sample ... | head -n 5`: no traceback, no message, exit 141 like a tool killed by SIGPIPE."""
    cmd = f"'{sys.executable}' -m scatter_cli sample '{SAMPLES / 'koala.obj'}' -n 3000000 | head -n 5"
    proc = run_user(["bash", "-c", cmd + "; echo \"status=${PIPESTATUS[0]}\""])
    lines = proc.stdout.decode().splitlines()
    assert lines[0] == "x,y,z" and len(lines) == 6 and lines[-1] == "status=141", lines
    assert proc.stderr == b"", proc.stderr


def test_closed_pipe_behind_a_named_path(tmp_path):
    """-o /dev/stdout onto a pipe whose reader leaves: the same quiet 141."""
    p = popen_user(scatter_command("sample", SAMPLES / "koala.obj", "-n", "3000000", "-f", "xyz", "-o", "/dev/stdout"),
                   stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    p.stdout.readline()
    p.stdout.close()
    err = p.stderr.read()
    assert p.wait(timeout=120) == 141 and err == b"", err


@pytest.mark.parametrize("sig,code,word", [(signal.SIGINT, 130, "interrupted"), (signal.SIGTERM, 143, "terminated")])
@pytest.mark.parametrize("target", ["existing", "new"])
def test_signal_in_the_middle_of_a_large_write(out, sig, code, word, target):
    folder, existing, new = out
    path = existing if target == "existing" else new
    p = popen_user(scatter_command("sample", SAMPLES / "koala.obj", "-n", "50000000", "-f", "csv", "-o", path),
                   stderr=subprocess.PIPE)
    # wait (no time limit asserted) until the temporary file holds data, then interrupt
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and p.poll() is None:
        parts = glob.glob(str(folder / ".*.part"))
        if parts and os.path.getsize(parts[0]) > (4 << 20):
            break
        time.sleep(0.02)
    assert p.poll() is None, "finished before it could be interrupted"
    p.send_signal(sig)
    err = p.stderr.read().decode()
    assert p.wait(timeout=120) == code, err
    assert err.strip() == f"error: {word}", err
    assert_clean(folder, existing, new)
