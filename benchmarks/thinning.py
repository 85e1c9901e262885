"""Time and quality of thin_to_count on a 1.3M-face icosphere.

Usage: python benchmarks/thinning.py [count] [repeats]
Prints, per oversampling factor k = candidates / count, the median wall time
of thin_to_count (time.perf_counter), the median CPU time of this process
(time.process_time; numpy runs single-threaded here, so on a busy shared
machine CPU time is the better estimate of unloaded wall time) and the
relative radius reached.
"""

import statistics
import sys
import time

import numpy as np
import trimesh

from scatter_cli.sampling.poisson.spacing import relative_radius, spacing_stats
from scatter_cli.sampling.poisson.thinning import thin_to_count


def main():
    count = int(sys.argv[1]) if len(sys.argv) > 1 else 100_000
    repeats = int(sys.argv[2]) if len(sys.argv) > 2 else 5
    mesh = trimesh.creation.icosphere(subdivisions=8)
    print(f"icosphere faces={len(mesh.faces)} area={mesh.area:.4f} count={count}")
    for k in (3, 5, 10):
        pts, _ = trimesh.sample.sample_surface(mesh, k * count, seed=k)
        pts = np.asarray(pts, dtype=np.float64)
        times, cpu = [], []
        for _ in range(repeats):
            t0, c0 = time.perf_counter(), time.process_time()
            idx, d_min = thin_to_count(pts, count, mesh.area)
            times.append(time.perf_counter() - t0)
            cpu.append(time.process_time() - c0)
        assert idx.size == count
        check = spacing_stats(pts[idx], mesh.area)
        rho = relative_radius(d_min, mesh.area, count)
        print(
            f"k={k:2d} candidates={pts.shape[0]:8d} median={statistics.median(times):.3f}s "
            f"cpu={statistics.median(cpu):.3f}s rho={rho:.4f} (check {check['rho']:.4f})"
        )


if __name__ == "__main__":
    main()
