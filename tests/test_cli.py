"""The command line through the real entry point: exit codes, one-line errors, atomic files."""

import re

import numpy as np
import pytest

from .conftest import popen_user, run_scatter, run_user, scatter_command, scatter_in_process


def assert_one_line_error(proc, code, *words):
    err = proc.stderr.decode()
    assert proc.returncode == code, err
    lines = [l for l in err.splitlines() if l.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    assert "Traceback" not in err
    for w in words:
        assert w in lines[0], (w, lines[0])


@pytest.fixture
def existing(tmp_path):
    out = tmp_path / "out.ply"
    out.write_bytes(b"precious")
    return out


def assert_untouched(existing):
    assert existing.read_bytes() == b"precious"
    assert not [p for p in existing.parent.iterdir() if p.name.startswith(".")], "temporary file left behind"


def write_obj(path, vertices, faces):
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in vertices] + [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.slow
def test_missing_file(tmp_path, existing):
    proc = run_scatter("sample", tmp_path / "nope.obj", "-o", existing)
    assert_one_line_error(proc, 1, "nope.obj", "no such file")
    assert_untouched(existing)


@pytest.mark.slow
def test_not_a_mesh(tmp_path, existing):
    bad = tmp_path / "bad.ply"
    bad.write_bytes(b"this is not a ply file\x00\x01\x02")
    assert_one_line_error(run_scatter("sample", bad, "-o", existing), 1, "bad.ply")
    assert_untouched(existing)


@pytest.mark.slow
def test_empty_file(tmp_path, existing):
    empty = tmp_path / "empty.stl"
    empty.write_bytes(b"")
    assert_one_line_error(run_scatter("sample", empty, "-o", existing), 1, "empty.stl", "empty")
    assert_untouched(existing)


def feed_fifo(path, data):
    """A named pipe at ``path`` that a thread fills with ``data`` once a reader opens it."""
    import os
    import threading

    os.mkfifo(path)

    def write():
        with open(path, "wb") as f:
            f.write(data)

    threading.Thread(target=write, daemon=True).start()
    return path


@pytest.mark.slow
@pytest.mark.skipif(not hasattr(__import__("os"), "mkfifo"), reason="named pipes")
def test_mesh_from_a_pipe_is_read_once(tmp_path, sample_mesh):
    # `scatter sample <(gunzip -c mesh.ply.gz)`: a pipe has no size and cannot be reread.
    data = sample_mesh("skull.ply").read_bytes()
    from_file = run_scatter("sample", sample_mesh("skull.ply"), "-n", 50, "-f", "xyz", check=True).stdout
    piped = run_scatter("sample", feed_fifo(tmp_path / "mesh.ply", data), "-n", 50, "-f", "xyz", check=True)
    assert piped.stdout == from_file
    no_suffix = feed_fifo(tmp_path / "mesh", data)
    assert_one_line_error(run_scatter("sample", no_suffix, "-n", 5), 2, "--input-format")
    with open(no_suffix, "rb") as f:  # let the writer finish
        f.read()
    assert_one_line_error(run_scatter("sample", feed_fifo(tmp_path / "none.ply", b""), "-n", 5), 1, "no data")


@pytest.mark.slow
def test_directory(tmp_path):
    assert_one_line_error(run_scatter("sample", tmp_path), 1, "directory")


@pytest.mark.slow
def test_mesh_without_faces(tmp_path):
    path = tmp_path / "points.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n")
    assert_one_line_error(run_scatter("sample", path), 1, "points.obj")


@pytest.mark.slow
def test_mesh_without_area(tmp_path, existing):
    path = write_obj(tmp_path / "flat.obj", [[0, 0, 0], [1, 0, 0], [2, 0, 0]], [[0, 1, 2], [0, 0, 1]])
    assert_one_line_error(run_scatter("sample", path, "-o", existing), 1, "flat.obj", "area")
    assert_untouched(existing)


@pytest.mark.slow
def test_non_finite_vertices_are_skipped_with_a_warning(tmp_path):
    path = write_obj(tmp_path / "nan.obj", [[0, 0, 0], [1, 0, 0], [0, 1, 0], [float("nan"), 0, 0]], [[0, 1, 2], [0, 1, 3]])
    proc = run_scatter("sample", path, "-n", 100, "-a", "face")
    assert proc.returncode == 0, proc.stderr
    assert "warning" in proc.stderr.decode() and "non-finite" in proc.stderr.decode()
    table = np.loadtxt(proc.stdout.decode().splitlines()[1:], delimiter=",")
    assert (table[:, 3] == 0).all() and np.isfinite(table).all()
    quiet = run_scatter("sample", path, "-n", 10, "-q")
    assert quiet.returncode == 0 and quiet.stderr == b""


@pytest.mark.slow
def test_all_vertices_non_finite(tmp_path):
    path = write_obj(tmp_path / "allnan.obj", [[float("nan"), 0, 0], [1, 0, 0], [0, float("inf"), 0]], [[0, 1, 2]])
    assert_one_line_error(run_scatter("sample", path), 1, "allnan.obj")


@pytest.mark.slow
@pytest.mark.parametrize(
    "args,words",
    [
        (["-n", "-5"], ["count"]),
        (["-n", "1.5"], ["count"]),
        (["-n", "ten"], ["count"]),
        (["--radius", "0"], ["radius"]),
        (["--radius", "-1"], ["radius"]),
        (["-a", "normal,sparkle"], ["sparkle"]),
        (["-a", "normal,smooth-normal"], ["normal"]),
        (["--method", "magic"], ["magic"]),
        (["--precision", "float16"], ["float16"]),
        (["-f", "e57"], ["e57"]),
        (["--seed", "-1"], ["seed"]),
        (["--chunk-size", "0"], ["chunk"]),
        (["--density", "-2"], ["density"]),
        (["-n", "10", "--density", "2"], ["density"]),
        (["--bogus-option"], ["bogus"]),
    ],
)
def test_usage_errors_exit_2(sample_mesh, existing, args, words):
    run = run_scatter if args == ["-n", "-5"] else scatter_in_process  # one in a real process
    proc = run("sample", sample_mesh("icosahedron_binary.stl"), "-o", existing, *args)
    assert_one_line_error(proc, 2, *words)
    assert_untouched(existing)


@pytest.mark.slow
def test_output_suffix_unknown(sample_mesh, tmp_path):
    assert_one_line_error(run_scatter("sample", sample_mesh("icosahedron_binary.stl"), "-o", tmp_path / "x.e57"), 2, "x.e57")


@pytest.mark.slow
def test_output_folder_missing(sample_mesh, tmp_path):
    out = tmp_path / "no" / "such" / "out.ply"
    assert_one_line_error(run_scatter("sample", sample_mesh("icosahedron_binary.stl"), "-o", out), 1, "does not exist")


@pytest.mark.slow
def test_attribute_the_mesh_cannot_provide(sample_mesh, existing):
    proc = run_scatter("sample", sample_mesh("icosahedron_binary.stl"), "-a", "uv", "-o", existing)
    assert_one_line_error(proc, 1, "uv", "icosahedron_binary.stl")
    assert_untouched(existing)


@pytest.mark.slow
def test_stdin_needs_input_format(sample_mesh):
    data = sample_mesh("icosahedron_binary.stl").read_bytes()
    assert_one_line_error(run_scatter("sample", "-", input=data), 2, "--input-format")
    proc = run_scatter("sample", "-", "--input-format", "stl", "-n", 10, "-f", "xyz", input=data, check=True)
    assert len(proc.stdout.decode().splitlines()) == 10


@pytest.mark.slow
def test_output_replaces_existing_file_atomically_on_success(sample_mesh, existing):
    run_scatter("sample", sample_mesh("icosahedron_binary.stl"), "-n", 10, "-o", existing, check=True)
    assert existing.read_bytes().startswith(b"ply\n")
    assert not [p for p in existing.parent.iterdir() if p.name.endswith(".part")]


@pytest.mark.slow
def test_new_file_gets_ordinary_permissions(sample_mesh, tmp_path):
    out = tmp_path / "perm.ply"
    run_scatter("sample", sample_mesh("icosahedron_binary.stl"), "-n", 10, "-o", out, check=True)
    assert out.stat().st_mode & 0o644 == 0o644


@pytest.mark.slow
def test_count_zero_writes_an_empty_valid_file(sample_mesh, tmp_path):
    out = tmp_path / "zero.npy"
    run_scatter("sample", sample_mesh("icosahedron_binary.stl"), "-n", 0, "-o", out, check=True)
    assert np.load(out).shape == (0,)


@pytest.mark.slow
def test_density_sets_the_count(sample_mesh):
    proc = run_scatter("sample", sample_mesh("icosahedron_binary.stl"), "--density", 100, "-f", "xyz", check=True)
    assert len(proc.stdout.decode().splitlines()) == round(100 * 9.574541)


@pytest.mark.slow
def test_stats_json(sample_mesh, tmp_path):
    import json

    stats = tmp_path / "s.json"
    run_scatter("sample", sample_mesh("icosahedron_binary.stl"), "-n", 100, "-o", tmp_path / "o.ply", "--stats", stats, check=True)
    info = json.loads(stats.read_text())
    assert info["count"] == 100 and abs(info["area"] - 9.574541) < 1e-5 and info["faces_used"] == 20
    assert "timings" in info


@pytest.mark.slow
def test_help_teaches():
    proc = run_scatter("sample", "--help", check=True)
    out = proc.stdout.decode()
    for word in ["--count", "--poisson", "--radius", "--attributes", "Examples", "square-root"]:
        assert word in out


@pytest.mark.slow
def test_closed_pipe_is_quiet(sample_mesh):
    import subprocess

    p = popen_user(scatter_command("sample", sample_mesh("koala.obj"), "-n", "2000000"),
                   stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    p.stdout.readline()
    p.stdout.close()
    err = p.stderr.read()
    p.wait(timeout=60)
    assert err == b"", err


@pytest.mark.slow
def test_progress_on_a_terminal_only(sample_mesh):
    import os
    import pty
    import subprocess

    # CSV: formatting text keeps this run well over the half second before the bar shows,
    # however fast the sampling kernel gets
    args = scatter_command("sample", sample_mesh("koala.obj"), "-n", "2000000", "-f", "csv", "-o", os.devnull)
    master, slave = pty.openpty()
    proc = run_user(args, stderr=slave, stdout=subprocess.DEVNULL, timeout=300)
    os.close(slave)
    seen = b""
    while True:
        try:
            data = os.read(master, 65536)
        except OSError:
            break
        if not data:
            break
        seen += data
    os.close(master)
    assert proc.returncode == 0
    assert b"sampling:" in seen and b"100.0%" in seen
    piped = run_user(args, timeout=300)
    assert piped.returncode == 0 and piped.stderr == b""


FULL = "/dev/full"


@pytest.mark.slow
@pytest.mark.skipif(not __import__("os").path.exists(FULL), reason="no /dev/full on this system")
@pytest.mark.parametrize("args", [
    ["sample", "{mesh}", "-n", "10"],
    ["sample", "{mesh}", "-n", "10", "-f", "ply"],
    ["sample", "{mesh}", "-n", "10", "-f", "npy"],
    ["info", "{mesh}"],
    ["info", "{mesh}", "--json"],
    ["--version"],
    ["sample", "--help"],
])
def test_standard_output_on_a_full_device(sample_mesh, args):
    """`scatter ... > /dev/full` with a user's buffered standard output: one line, exit 1."""
    args = [sample_mesh("icosahedron_binary.stl") if a == "{mesh}" else a for a in args]
    with open(FULL, "wb") as full:
        proc = run_scatter(*args, stdout=full)
    assert_one_line_error(proc, 1, "standard output", "cannot write", "No space left")


def test_children_run_in_a_users_environment(monkeypatch):
    import sys

    monkeypatch.setenv("PYTHONUNBUFFERED", "1")
    monkeypatch.setenv("CI", "true")
    code = "import os, sys; print(sorted(k for k in ('PYTHONUNBUFFERED', 'CI') if k in os.environ), repr(sys.stdin.read()))"
    assert run_user([sys.executable, "-c", code], timeout=30).stdout.decode().split() == ["[]", "''"]


def test_tests_start_children_through_conftest():
    """Every subprocess in tests/ goes through conftest's helpers (a user's environment)."""
    import re
    from pathlib import Path

    here = Path(__file__).parent
    direct = [f"{p.name}:{n}" for p in sorted(here.glob("*.py")) if p.name != "conftest.py"
              for n, line in enumerate(p.read_text().splitlines(), 1)
              if re.search(r"subprocess\.(run|Popen|call|check_call|check_output)\(|os\.(system|popen)\(", line)]
    assert not direct, direct


@pytest.mark.slow
def test_version():
    from scatter_cli import version

    proc = run_scatter("--version", check=True)
    assert proc.stdout.decode() == f"scatter {version()}\n"
    assert version()[0].isdigit()


@pytest.mark.slow
def test_help_lists_every_format_and_attribute():
    from scatter_cli.run.fields import ATTRIBUTES
    from scatter_cli.writers.formats import FORMATS

    text = " ".join(run_scatter("sample", "--help", check=True).stdout.decode().split())
    text = re.sub(r"(\w)- (\w)", r"\1-\2", text)  # click wraps lines after a hyphen
    assert "|".join(FORMATS) in text
    assert ", ".join(ATTRIBUTES) in text


def option_flags(parameter):
    """The flags (``-n``, ``--count``) of an option as the command line declares it."""
    info = parameter.annotation.__metadata__[0]
    return [d for d in (info.default, *info.param_decls) if isinstance(d, str) and d.startswith("-")]


def sample_options_not_listed(command, help_text):
    """The sample options ``command`` takes (cli.SAMPLE_OPTIONS, declared once) whose flags
    its ``--help`` does not list."""
    import re

    from scatter_cli import cli

    entries = [re.match(r"  (-[^\s,]+(?:, -[^\s,]+)*)", line) for line in help_text.splitlines()]
    listed = {flag for entry in entries if entry for flag in entry.group(1).split(", ")}
    return [name for name in getattr(cli, command).sample_options
            if not set(option_flags(cli.SAMPLE_OPTIONS[name])) <= listed]


@pytest.mark.parametrize("command", ["sample", "batch", "preview"])
def test_help_lists_every_sample_option_a_command_takes(command):
    from scatter_cli import cli

    assert getattr(cli, command).sample_options
    assert sample_options_not_listed(command, run_scatter(command, "--help", check=True).stdout.decode()) == []


def test_a_sample_option_dropped_from_a_command_is_missed_in_its_help(monkeypatch):
    import inspect

    from click.testing import CliRunner

    from scatter_cli import cli

    signature = inspect.signature(cli.batch)
    monkeypatch.setattr(cli.batch, "__signature__",
                        signature.replace(parameters=[p for p in signature.parameters.values() if p.name != "seed"]))
    text = CliRunner().invoke(cli.command(), ["batch", "--help"]).output
    assert "--skip-existing" in text and sample_options_not_listed("batch", text) == ["seed"]


def test_the_sample_options_are_the_fields_of_a_run_and_the_output_options():
    """Each declared option reaches SampleOptions.of under its field's name, or is an
    option of the output (format, ASCII, coordinate system); only the Python API sets
    the oversampling of Poisson thinning."""
    import dataclasses

    from scatter_cli import cli
    from scatter_cli.run.options import SampleOptions

    def unmatched(declared):
        fields = {f.name for f in dataclasses.fields(SampleOptions)}
        return set(declared) ^ fields

    assert unmatched(cli.SAMPLE_OPTIONS) == {"fmt", "ascii", "crs", "oversampling"}
    assert set(cli.sample.sample_options) == set(cli.SAMPLE_OPTIONS)
    assert unmatched([*cli.SAMPLE_OPTIONS, "chunksize"]) == {"fmt", "ascii", "crs", "oversampling", "chunksize"}


@pytest.mark.slow
def test_debug_shows_the_traceback_of_an_internal_error(sample_mesh):
    import sys

    def run(*args):
        # sys.argv holds --debug in both runs: the option is read through typer, not sys.argv
        code = ("import sys\nfrom scatter_cli import api, cli\n"
                "def broken(*a, **k): raise RuntimeError('broken on purpose')\n"
                f"api.prepare = broken\nsys.argv = ['scatter', '--debug']\nsys.exit(cli.main({list(args)!r}))")
        return run_user([sys.executable, "-c", code])

    mesh = str(sample_mesh("icosahedron_binary.stl"))
    assert_one_line_error(run("sample", mesh), 1, "internal error", "RuntimeError", "--debug")
    debug = run("--debug", "sample", mesh)
    err = debug.stderr.decode()
    assert debug.returncode == 1 and "Traceback" in err and "broken on purpose" in err, err


@pytest.mark.slow
@pytest.mark.parametrize("threads", ["abc", "1.5"])
def test_bad_thread_count_is_a_usage_error(sample_mesh, threads):
    proc = run_scatter("sample", sample_mesh("icosahedron_binary.stl"), "-n", 10, env={"SCATTER_THREADS": threads})
    assert_one_line_error(proc, 2, "SCATTER_THREADS", threads)


# ---------------------------------------------------------------------------
# usage lines and counts as users type them


@pytest.mark.slow
def test_scatter_alone_prints_the_usage_line_and_a_hint(tmp_path):
    proc = run_scatter()
    err = proc.stderr.decode().splitlines()
    assert proc.returncode == 2 and proc.stdout == b""
    assert err[0] == "Usage: scatter [OPTIONS] COMMAND [ARGS]..." and "scatter --help" in err[1]
    assert len(err) == 2  # not the whole help: no option or command list


@pytest.mark.slow
@pytest.mark.parametrize("command", ["sample", "info", "check", "bench", "batch", "merge"])
def test_usage_lines_have_no_braces(command):
    usage = run_scatter(command, "--help", check=True).stdout.decode().splitlines()[0]
    assert usage.startswith(f"Usage: scatter {command} ") and "{" not in usage and "}" not in usage, usage


@pytest.mark.slow
def test_a_missing_mesh_is_one_line_naming_it():
    assert_one_line_error(run_scatter("sample"), 2, "MESH", "--help")


@pytest.mark.slow
@pytest.mark.parametrize("command", ["sample", "batch"])
def test_counts_and_densities_in_scientific_notation(sample_mesh, tmp_path, command):
    mesh = sample_mesh("icosahedron_binary.stl")

    def written(*options):
        out = tmp_path / f"{command}-{len(list(tmp_path.iterdir()))}"
        out.mkdir()
        target = out / "p.npy" if command == "sample" else out / "{stem}.npy"
        # (sample through the command's entry point in this process; its error below and
        # every batch in a real process)
        (run_scatter if command == "batch" else scatter_in_process)(command, mesh, *options, "-o", target, check=True)
        return next(out.iterdir()).read_bytes()  # its only file

    assert written("-n", "1e3") == written("-n", "1000") == written("-n", "1.0e3")
    assert len(written("-n", "1e3")) > len(written("-n", "999"))
    assert written("--density", "2.5e1") == written("--density", "25")
    proc = run_scatter(command, mesh, "-n", "1.5", "-o", tmp_path / ("x.npy" if command == "sample" else "{stem}.npy"))
    assert_one_line_error(proc, 2, "'1.5' is not a whole number", "--count")
    assert not (tmp_path / "x.npy").exists()
