"""Fuzz the mesh loaders with mutated PLY/OBJ/STL/OFF/GLB bytes: one command, prints results.

    PYTHONPATH=. python benchmarks/fuzz_loaders.py [--inputs 20000] [--seed 0] [--only glb ...]

Every input must load and sample, or fail with a ScatterError (one-line `error:`); and
where the fast readers (scatter_cli/loading/fast.py) answer, trimesh must load the same
triangles. Any other outcome is printed with the input that caused it (saved under
--save); an input that takes more than --hang seconds stops the run, left in --save.
benchmarks/sanitize_readers.sh runs this under ASan and UBSan.
"""

import argparse
import collections
import faulthandler
import os
import sys
import tempfile
import time
import traceback

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from testkit.fuzz_inputs import SEEDS, differential, exercise, mutate, random_ops  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--inputs", type=int, default=20000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--save", default="fuzz-crashes")
    ap.add_argument("--only", nargs="*", help="seed names to mutate (default: all)")
    ap.add_argument("--hang", type=float, default=120, help="seconds one input may take before the run stops")
    args = ap.parse_args()
    os.makedirs(args.save, exist_ok=True)
    rng = np.random.default_rng(args.seed)
    names = sorted(args.only or SEEDS)
    outcomes = collections.Counter()
    crashes = collections.Counter()
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as work:
        for i in range(args.inputs):
            name = names[i % len(names)]
            suffix, seed = SEEDS[name]
            data = mutate(seed, random_ops(rng))
            # a hang (a loop in compiled code holds the thread): the watchdog prints the
            # stack and exits, and the input is left in --save as pending.SUFFIX
            pending = os.path.join(args.save, f"pending.{suffix}")
            with open(pending, "wb") as f:
                f.write(data)
            faulthandler.dump_traceback_later(args.hang, exit=True)
            try:
                outcomes[(name, exercise(data, suffix, work))] += 1
                outcomes[(name, differential(data, suffix, work))] += 1
            except Exception as exc:  # a crash: would surface as 'internal error'
                key = f"{name}: {type(exc).__name__}: {str(exc)[:80]}"
                if not crashes[key]:
                    with open(os.path.join(args.save, f"crash-{len(crashes)}.{suffix}"), "wb") as f:
                        f.write(data)
                    print("CRASH", key, "\n", "".join(traceback.format_exception(exc)[-3:]), file=sys.stderr)
                crashes[key] += 1
                outcomes[(name, "crash")] += 1
            faulthandler.cancel_dump_traceback_later()
            os.remove(pending)
            if (i + 1) % 1000 == 0:
                print(f"{i + 1} inputs, {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    dt = time.perf_counter() - t0
    print(f"{args.inputs} inputs in {dt:.0f} s")
    for name in names:
        print(f"  {name:11s} " + "  ".join(f"{k}={outcomes[(name, k)]}" for k in ("ok", "error", "same", "handed", "crash")))
    print(f"distinct crashes: {len(crashes)}")
    for k, v in crashes.most_common():
        print(f"  {v:6d}  {k}")
    return 1 if crashes else 0


if __name__ == "__main__":
    sys.exit(main())
