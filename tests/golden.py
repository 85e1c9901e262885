"""Pinned output bytes: the sha256 of what each of a fixed list of commands writes.

``python tests/golden.py`` runs every command once in this process (the real command
line, ``scatter_cli.cli.main``) and prints ``{name: sha256}`` as JSON; with ``--update``
it rewrites ``tests/golden_digests.json``. ``tests/test_golden.py`` runs it with the
compiled kernels and with ``SCATTER_NUMPY=1`` and holds both to the pinned digests, so
a change that moves code cannot move a byte of output unnoticed.

A command writes ``out.EXT`` (or standard output, or a folder for ``batch``) in a fresh
temporary folder; its digest covers every file it wrote, by name.
"""

from __future__ import annotations

import hashlib
import json
import os
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SAMPLES = ROOT / "samples"
DIGESTS = Path(__file__).resolve().parent / "golden_digests.json"

S = {name: str(SAMPLES / name) for name in os.listdir(SAMPLES)}
SKULL, SPOT, TRUCK = S["skull.ply"], S["spot_triangulated.obj"], S["cesiummilktruck.glb"]
ICO, HEMI, PED = S["icosahedron_binary.stl"], S["hemisphere.off"], S["pediment_join_plate_12.stl"]
COLORBOX, TEXBOX = S["boxvertexcolors.glb"], S["boxtextured.glb"]
MOEBIUS, NARROW, KOALA = S["moebius-160-10.ply"], S["narrow_triangles.obj"], S["koala.obj"]

# name -> (argv, standard input file or None); "OUT" stands for the output path.
COMMANDS = {
    "skull-plain": (["sample", SKULL, "-n", "20000", "-o", "OUT.ply"], None),
    "skull-chunked": (["sample", SKULL, "-n", "20000", "--chunk-size", "777", "-o", "OUT.ply"], None),
    "spot-attributes": (["sample", SPOT, "-n", "5000", "-a", "normal,face,bary,uv", "-o", "OUT.ply"], None),
    "spot-stratified": (["sample", SPOT, "-n", "5000", "--method", "stratified", "-a", "normal", "-o", "OUT.ply"], None),
    "spot-sobol": (["sample", SPOT, "-n", "5000", "--method", "sobol", "-a", "face", "-o", "OUT.ply"], None),
    "koala-smooth": (["sample", KOALA, "-n", "10000", "-a", "smooth-normal", "--seed", "7", "-o", "OUT.ply"], None),
    "ico-poisson": (["sample", ICO, "--poisson", "-n", "500", "-o", "OUT.ply"], None),
    "hemi-radius": (["sample", HEMI, "--radius", "0.05", "-a", "normal", "-o", "OUT.ply"], None),
    "hemi-density": (["sample", HEMI, "--density", "500", "-o", "OUT.ply"], None),
    "spot-stable": (["sample", SPOT, "--stable", "-n", "5000", "-a", "normal", "-o", "OUT.ply"], None),
    "spot-stable-radius": (["sample", SPOT, "--stable", "--radius", "0.03", "-o", "OUT.ply"], None),
    "spot-stable-density": (["sample", SPOT, "--stable", "--density", "800", "-a", "bary", "-o", "OUT.ply"], None),
    "truck-exterior": (["sample", TRUCK, "--exterior", "-n", "5000", "-a", "normal,object", "-o", "OUT.ply"], None),
    "truck-exterior-poisson": (["sample", TRUCK, "--exterior", "--poisson", "-n", "400", "-o", "OUT.ply"], None),
    "truck-stable-exterior": (["sample", TRUCK, "--stable", "--exterior", "-n", "3000", "-o", "OUT.ply"], None),
    "truck-scene": (["sample", TRUCK, "-n", "5000", "-a", "object,orient,smooth-normal", "-o", "OUT.ply"], None),
    "truck-color": (["sample", TRUCK, "-n", "3000", "-a", "color", "-o", "OUT.ply"], None),
    "colorbox-weight": (["sample", COLORBOX, "-n", "2000", "--weight", "vertex-color:r", "-a", "color", "-o", "OUT.ply"], None),
    "texbox-weight": (["sample", TEXBOX, "-n", "2000", "--weight", "texture:g", "-a", "color,uv", "-o", "OUT.ply"], None),
    "pediment-csv": (["sample", PED, "-n", "3000", "-a", "normal,face", "-o", "OUT.csv"], None),
    "pediment-xyz": (["sample", PED, "-n", "3000", "-o", "OUT.xyz"], None),
    "pediment-npy": (["sample", PED, "-n", "3000", "-a", "bary,face", "-o", "OUT.npy"], None),
    "colorbox-pcd": (["sample", COLORBOX, "-n", "2000", "-a", "normal,color", "-o", "OUT.pcd"], None),
    "colorbox-pcd-ascii": (["sample", COLORBOX, "-n", "500", "-a", "color", "--ascii", "-o", "OUT.pcd"], None),
    "skull-las": (["sample", SKULL, "-n", "5000", "-a", "face", "-o", "OUT.las"], None),
    "skull-laz": (["sample", SKULL, "-n", "5000", "-a", "normal", "-o", "OUT.laz"], None),
    "colorbox-las-color": (["sample", COLORBOX, "-n", "1000", "-a", "color", "-o", "OUT.las"], None),
    "spot-usda": (["sample", SPOT, "-n", "2000", "-a", "normal,uv", "-o", "OUT.usda"], None),
    "truck-usda-orient": (["sample", TRUCK, "-n", "1000", "-a", "orient", "-o", "OUT.usda"], None),
    "moebius-ascii": (["sample", MOEBIUS, "-n", "2000", "--ascii", "-a", "normal", "-o", "OUT.ply"], None),
    "moebius-float64": (["sample", MOEBIUS, "-n", "2000", "--precision", "float64", "-o", "OUT.ply"], None),
    "skull-shard": (["sample", SKULL, "-n", "20000", "--shard", "1/3", "-o", "OUT.ply"], None),
    "stdin-ply": (["sample", "-", "--input-format", "ply", "-n", "2000", "-o", "OUT.ply"], MOEBIUS),
    "stdout-csv": (["sample", NARROW, "-n", "1000", "-a", "normal"], None),
    "spot-volume-box": (["sample", SPOT, "--volume", "-n", "2000", "-a", "sdf,inside,winding,closest,face", "-o",
                         "OUT.ply"], None),
    "spot-near-float64": (["sample", SPOT, "--near", "0.02,0.005,0.001", "--box-share", "0.1", "-n", "2000", "-a",
                           "sdf,inside,winding,closest,face", "--precision", "float64", "-o", "OUT.npy"], None),
    "spot-deepsdf": (["sample", SPOT, "--normalize", "unit-sphere", "--near", "0.0707,0.0224", "--box-share", "0.06",
                      "-a", "sdf", "-n", "2000", "-o", "OUT.npy"], None),
    "truck-near-scene": (["sample", TRUCK, "--near", "0.05", "--box-share", "0.5", "-n", "2000", "-a",
                          "sdf,inside,closest,face,object", "-o", "OUT.ply"], None),
    "hemi-volume-parity": (["sample", HEMI, "--volume", "--sign", "parity", "-n", "2000", "-a", "inside,sdf,winding",
                            "--precision", "float64", "-o", "OUT.csv"], None),
    "pediment-edges": (["sample", PED, "-n", "3000", "--edges", "0.5", "-a", "normal,face,sharp", "-o", "OUT.ply"],
                       None),
    "truck-edges-scene": (["sample", TRUCK, "-n", "2000", "--edges", "0.3", "--sharp-angle", "30", "-a",
                           "object,orient,bary,sharp", "-o", "OUT.npy"], None),
    "spot-near-edges": (["sample", SPOT, "--near", "0.01,0.002", "--edges", "0.25", "--near-edges", "0.001",
                         "--box-share", "0.2", "-n", "2000", "-a", "sdf,sharp", "--precision", "float64", "-o",
                         "OUT.npy"], None),
    "batch": (["batch", ICO, HEMI, NARROW, PED, "-o", "OUT/{stem}.ply", "-n", "300", "-a", "normal,face", "-j", "2",
               "-q"], None),
}


def digest(folder: Path, stdout: Path) -> str:
    """sha256 over every file a command wrote, names and bytes, in sorted order."""
    h = hashlib.sha256()
    files = sorted(p for p in folder.rglob("*") if p.is_file() and p != stdout)
    if stdout.stat().st_size:
        files.append(stdout)
    for p in files:
        h.update(p.relative_to(folder).as_posix().encode() + b"\0")
        h.update(p.read_bytes())
    return h.hexdigest()


def run_one(argv, stdin, folder: Path) -> str:
    from scatter_cli.cli import main

    argv = [a.replace("OUT", str(folder / "out")) for a in argv]
    stdout = folder / ".stdout"
    saved = os.dup(0), os.dup(1)
    with open(stdout, "wb") as out, open(stdin or os.devnull, "rb") as inp:
        sys.stdout.flush()
        os.dup2(out.fileno(), 1)
        os.dup2(inp.fileno(), 0)
        try:
            code = main(argv)
            sys.stdout.flush()
        finally:
            os.dup2(saved[0], 0)
            os.dup2(saved[1], 1)
            os.close(saved[0])
            os.close(saved[1])
    if code != 0:
        raise SystemExit(f"golden: scatter {' '.join(argv)} exited {code}")
    return digest(folder, stdout)


def run_all(names=None) -> dict:
    result = {}
    for name, (argv, stdin) in COMMANDS.items():
        if names and name not in names:
            continue
        with tempfile.TemporaryDirectory() as tmp:
            result[name] = run_one(argv, stdin, Path(tmp))
    return result


if __name__ == "__main__":
    digests = run_all(sys.argv[2:] if len(sys.argv) > 2 and sys.argv[1] == "--only" else None)
    if "--update" in sys.argv[1:]:
        DIGESTS.write_text(json.dumps(digests, indent=1, sort_keys=True) + "\n")
    json.dump(digests, sys.stdout, indent=1, sort_keys=True)
    sys.stdout.write("\n")
