"""The text readers (`_creaders.c`) under AddressSanitizer and UndefinedBehaviorSanitizer,
read in parts on several threads.

Builds scatter_cli/loading/_creaders.c with -fsanitize=address,undefined into a copy of
the package (and of the tests and benchmarks) in a temporary directory, then, with the
sanitizer runtimes preloaded, runs tests/test_readers.py but its memory bounds (every
reader against trimesh; ASCII STL, OFF, ASCII PLY and OBJ files cut in parts, with CRLF,
lone CR, blank lines, polygons, materials, extra columns, junk and errors late in the
file, on 1, 2, 3 and 7 threads). Then it reads the icosphere(7) (327,680 faces) as OFF,
ASCII PLY and OBJ, and 40 copies of the icosphere(6)'s files cut short or with a byte
changed, on 1 to 15 threads, comparing each with the one-thread answer. Any report aborts.

    python benchmarks/readers_sanitizers.py      (gcc with libasan/libubsan; Linux)

benchmarks/sanitize_readers.sh fuzzes the same readers with mutated small files.
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from sanitized import run_sanitized  # noqa: E402

BIG = r'''
import numpy as np, trimesh, io
from scatter_cli.loading import _creaders
from scatter_cli.loading.fast import _ascii_layout

def exported(mesh, name):
    out = io.BytesIO()
    mesh.export(out, file_type=name, **({"encoding": "ascii"} if name == "ply" else {}))
    return out.getvalue()

big, small = trimesh.creation.icosphere(subdivisions=7), trimesh.creation.icosphere(subdivisions=6)

def read(name, data, threads):
    if name == "obj":
        return _creaders.read_obj(data, threads % 2 == 0, threads)  # (with and without UVs and normals)
    if name == "off":
        return _creaders.read_off(data, threads)
    layout = _ascii_layout(data)
    return None if layout is None else _creaders.read_ply_ascii(data, *layout[0], b"", threads)

def same(a, b):
    return (a is None and b is None) or (a is not None and b is not None and all(
        (x.tobytes() == y.tobytes()) if isinstance(x, np.ndarray) else x == y for x, y in zip(a, b)))

rng = np.random.default_rng(0)
for name in ("off", "ply", "obj"):
    data = exported(big, name)
    whole = read(name, data, 1)
    assert whole is not None and len(whole[1]) == len(big.faces), name
    for threads in (3, 7, 15):  # (odd: an OBJ read as with one thread, without its UVs and normals)
        assert same(read(name, data, threads), whole), (name, threads)
    data = exported(small, name)
    for k in range(40):  # cut short, or a byte damaged, in the second half
        cut = bytearray(data[: int(rng.integers(len(data) // 2, len(data) + 1))])
        if k % 2:
            cut[int(rng.integers(len(cut) // 2, len(cut)))] = int(rng.choice([0x20, 0x0A, 0x0D, 0x2D, 0x78, 0x30]))
        cut = bytes(cut)
        one = read(name, cut, 1)
        for threads in (3, 5):
            assert same(read(name, cut, threads), one), (name, k, threads)
    print(f"readers: {name}, the icosphere(7) whole and 40 cut or damaged copies of the icosphere(6), 1 to 15 "
          "threads, under the sanitizers: the one-thread answer every time")
'''


def main():
    # (not the memory bounds: the sanitizers' own allocator and shadow memory count there)
    run_sanitized("_creaders", "loading.fast", ["tests/test_readers.py", "-k", "not takes_at_most"], BIG)


if __name__ == "__main__":
    main()
