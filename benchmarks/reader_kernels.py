"""The OFF, ASCII PLY and OBJ readers (`_creaders`) of two checkouts, call after call.

    python benchmarks/reader_kernels.py BEFORE AFTER [--rounds 9] [--subdivisions 8]

BEFORE and AFTER are folders holding a built `scatter_cli` (their kernels built in
place). The icosphere (default: 8 subdivisions, 1,310,720 faces; about 50 MB of text
each) is written by trimesh as an OFF, an ASCII PLY and an OBJ and read from memory by both
kernels in turn, on 1 and 2 threads (a kernel that takes no thread count reads on one);
medians of the wall times, and whether both gave the same arrays.
"""

import argparse
import io
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from builds import kernel_of  # noqa: E402
from scatter_cli.loading.fast import _ascii_layout  # noqa: E402


def reader(kernel, kind, data, threads):
    """A call of ``kernel``'s reader of ``kind`` on ``data`` with ``threads`` where it takes them."""
    layout = _ascii_layout(data)[0] if kind == "ply" else None
    with_threads = {"off": lambda t: kernel.read_off(data, t), "obj": lambda t: kernel.read_obj(data, False, t),
                    "ply": lambda t: kernel.read_ply_ascii(data, *layout, b"", t)}[kind]
    try:
        with_threads(1)
    except TypeError:  # a kernel from before the readers took a thread count: one thread
        return {"off": lambda: kernel.read_off(data), "obj": lambda: kernel.read_obj(data, False),
                "ply": lambda: kernel.read_ply_ascii(data, *layout)}[kind]
    return lambda: with_threads(threads)


def main():
    import trimesh

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("before")
    parser.add_argument("after")
    parser.add_argument("--rounds", type=int, default=9)
    parser.add_argument("--subdivisions", type=int, default=8)
    args = parser.parse_args()
    mesh = trimesh.creation.icosphere(subdivisions=args.subdivisions)
    kernels = {tag: kernel_of(folder, "_creaders", tag) for tag, folder in (("before", args.before), ("after", args.after))}
    print(f"icosphere({args.subdivisions}), {len(mesh.faces):,} faces, median of {args.rounds} rounds after a warm-up")
    for kind in ("off", "ply", "obj"):
        out = io.BytesIO()
        mesh.export(out, file_type=kind, **({"encoding": "ascii"} if kind == "ply" else {}))
        data = out.getvalue()
        calls = {f"{name}, {t} thread{'s' * (t > 1)}": reader(k, kind, data, t) for name, k in kernels.items()
                 for t in (1, 2)}
        times = {name: [] for name in calls}
        answers = {}
        for _ in range(args.rounds + 1):
            for name, call in calls.items():
                t = time.perf_counter()
                answers[name] = call()
                times[name].append(time.perf_counter() - t)
        first = next(iter(answers.values()))
        same = all(all((a.tobytes() == b.tobytes()) if hasattr(a, "tobytes") else a == b for a, b in zip(got, first))
                   for got in answers.values())
        print(f"{kind.upper()}, {len(data) / 2**20:.0f} MB: " + ", ".join(
            f"{name} {statistics.median(times[name][1:]):.3f} s" for name in calls) + f"; same arrays: {same}")


if __name__ == "__main__":
    main()
