"""Our point files read back: ``merge`` and ``preview`` read a file through the same reader
(its format module's ``read``), so they agree about every file, sound or broken; and a
malformed PLY header is the same one-line error in ``merge``, ``preview`` and ``sample``."""

import numpy as np
import pytest

from scatter_cli.commands import preview as PREVIEW
from scatter_cli.commands.merge import merge
from scatter_cli.errors import ScatterError
from scatter_cli.loading import load as loaders
from scatter_cli.loading.load import load_surface
from scatter_cli.writers import pointfiles
from scatter_cli.writers.pointfiles import PointFile

from .conftest import SAMPLES, run_user, scatter_command, scatter_in_process

COUNT = 300
FILES = {  # name -> (suffix, sample options)
    "ply": ("ply", ()), "ply-ascii": ("ply", ("--ascii",)), "csv": ("csv", ()), "xyz": ("xyz", ()),
    "npy": ("npy", ()), "pcd": ("pcd", ()), "pcd-ascii": ("pcd", ("--ascii",)), "las": ("las", ()),
    "laz": ("laz", ()),
}
COUNT_LINES = {"ply": b"element vertex %d", "npy": b"'shape': (%d,)", "pcd": b"POINTS %d"}


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    """The files ``scatter sample`` writes, one per format (the command run in this process:
    what is checked here is the files)."""
    folder = tmp_path_factory.mktemp("written")
    for name, (suffix, options) in FILES.items():
        scatter_in_process("sample", SAMPLES / "spot_triangulated.obj", "-n", COUNT, "-a", "normal", *options,
                           "-o", folder / f"{name}.{suffix}", check=True)
    return folder


def variants(data, suffix):
    """{variant: bytes} of a file as written: itself, cut short, with a row or bytes more,
    and with a header that counts one point more."""
    out = {"as written": data, "truncated": data[:-3]}
    text = data.endswith(b"\n")
    out["one more row" if text else "bytes after"] = data + (data[data.rindex(b"\n", 0, -1) + 1 :] if text else bytes(5))
    key = COUNT_LINES.get(suffix)
    if key and key % COUNT in data:
        out["counted one more"] = data.replace(key % COUNT, key % (COUNT + 1), 1)
    return out


def outcomes(path, tmp_path):
    """(what merge makes of the file given twice, what preview makes of it): the points
    each reads (merge's: those of the file it writes, read back whole) or the error."""
    joined = tmp_path / f"joined{path.suffix}"
    try:
        merge([path, path], joined)
        merged = pointfiles.read_file(joined).columns()
        merged = np.stack([merged[c] for c in "xyz"], axis=1)
    except ScatterError as exc:
        merged = str(exc)
    try:
        points = PREVIEW.load(str(path), None)[0]
        seen = np.concatenate([points, points])
    except ScatterError as exc:
        seen = str(exc)
    return merged, seen


def agree(merged, seen):
    if isinstance(merged, str) or isinstance(seen, str):
        return isinstance(merged, str) and isinstance(seen, str) and merged == seen
    return merged.shape == seen.shape and np.array_equal(merged, seen)


@pytest.mark.parametrize("name", FILES)
def test_merge_and_preview_read_every_file_the_same_way(name, written, tmp_path):
    suffix = FILES[name][0]
    data = (written / f"{name}.{suffix}").read_bytes()
    read = {}
    for variant, content in variants(data, suffix).items():
        path = tmp_path / f"{variant.replace(' ', '-')}.{suffix}"
        path.write_bytes(content)
        merged, seen = outcomes(path, tmp_path)
        assert agree(merged, seen), (variant, merged if isinstance(merged, str) else seen)
        read[variant] = merged
    assert not isinstance(read["as written"], str) and len(read["as written"]) == 2 * COUNT
    truncated = read["truncated"]
    assert isinstance(truncated, str) and truncated.startswith(f"{tmp_path / 'truncated'}.{suffix}: ")


def test_the_agreement_fails_a_preview_that_reads_files_its_own_way(written, tmp_path, monkeypatch):
    """The broken variant: preview with a reader of its own that does not check a file's
    body against its header (as its own PLY reader did). A PLY with bytes after its points
    is then drawn by preview and refused by merge, and the comparison above says so."""
    def unchecked(cls, path, dtype, count, offset, binary, layout, head, sep=None):
        return cls(path, dtype, count, offset, pointfiles.file_bytes(path), binary, layout, head, sep)

    real_load = PREVIEW.load

    def preview_on_its_own(path, options):
        with pytest.MonkeyPatch.context() as m:
            m.setattr(PointFile, "checked", classmethod(unchecked))
            return real_load(path, options)

    path = tmp_path / "bytes-after.ply"
    path.write_bytes((written / "ply.ply").read_bytes() + bytes(5))
    assert agree(*outcomes(path, tmp_path))
    monkeypatch.setattr(PREVIEW, "load", preview_on_its_own)
    merged, seen = outcomes(path, tmp_path)
    assert isinstance(merged, str) and not isinstance(seen, str) and not agree(merged, seen)


# -- a malformed PLY header: one parser, one error ----------------------------------------

MESH_HEADER = (b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
               b"element face 1\nproperty list uchar int vertex_indices\nend_header\n")
MESH_BODY = b"0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"
MALFORMED = {  # what is wrong -> (the header, the error's words)
    "a count in letters": (MESH_HEADER.replace(b"vertex 3", b"vertex three"),
                           "malformed PLY header at line 3: 'element vertex three'"),
    "an unknown type": (MESH_HEADER.replace(b"float y", b"flaot y"), "malformed PLY header at line 5: 'property flaot y'"),
    "no end_header": (MESH_HEADER.replace(b"end_header\n", b""), "malformed PLY header: no end_header line"),
    "not a PLY": (MESH_HEADER.replace(b"ply\n", b"pyl\n", 1), "not a PLY file (its first line is not 'ply')"),
}


@pytest.mark.parametrize("case", MALFORMED)
def test_a_malformed_ply_header_is_one_error_in_merge_preview_and_sample(case, tmp_path, monkeypatch):
    """Each command's words and exit code; the first case through real processes (what a
    shell sees), the others through the commands in this process."""
    header, words = MALFORMED[case]
    (tmp_path / "bad.ply").write_bytes(header + MESH_BODY)
    expected = f"error: bad.ply: {words}"
    monkeypatch.chdir(tmp_path)
    for args in (["merge", "bad.ply", "bad.ply", "-o", "m.ply"], ["preview", "bad.ply", "-o", "s.png"],
                 ["sample", "bad.ply", "-o", "o.csv"]):
        if case == next(iter(MALFORMED)):
            proc = run_user(scatter_command(*args), cwd=tmp_path)
        else:
            proc = scatter_in_process(*args)
        lines = proc.stderr.decode().splitlines()
        assert proc.returncode == 1 and lines[0].startswith(expected), (args, lines)
        assert "Traceback" not in proc.stderr.decode()
    assert not (tmp_path / "m.ply").exists() and not (tmp_path / "o.csv").exists()


def errors_of(path, tmp_path):
    """The errors that merge, preview and the mesh loader (what sample reads with) give for ``path``."""
    said = []
    for read in (lambda: merge([path], tmp_path / "m.ply"), lambda: PREVIEW.load(str(path), None),
                 lambda: load_surface(str(path))):
        with pytest.raises(ScatterError) as caught:
            read()
        said.append(str(caught.value))
    return said


def test_the_one_error_fails_a_loader_that_keeps_trimesh_s_words(tmp_path, monkeypatch):
    """The broken variant: a mesh loader that does not ask the PLY header parser when
    trimesh fails words the same file otherwise, and the comparison catches it."""
    path = tmp_path / "bad.ply"
    path.write_bytes(MALFORMED["a count in letters"][0] + MESH_BODY)
    assert len(set(errors_of(path, tmp_path))) == 1
    monkeypatch.setattr(loaders.ply, "header_error", lambda head: None)
    assert len(set(errors_of(path, tmp_path))) == 2

