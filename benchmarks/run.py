"""Benchmark scatter against its peers, all measured in the same run.

    python benchmarks/run.py [--quick] [--out DIR] [--mesh REAL_MESH] [--only SECTIONS]

Sections:
  uniform  in-process sampling time and peak memory: trimesh, pymeshlab, Open3D,
           point-cloud-utils, ours, and the numpy "floor" (3N random doubles
           written into an (N, 3) float32 array).
  e2e      wall time of whole commands: `scatter sample`, CloudCompare, a
           five-line trimesh script, and interpreter start-up baselines.
  poisson  Poisson-disk sampling: time, points returned, and
           rho = d_min / sqrt(2A / (sqrt(3) N)).

Every in-process measurement runs in its own child process (this script with
--child): the child loads the mesh, does one warm-up run, then times back-to-back
runs and reports the median. Peak memory is the child's VmHWM during a run minus
its RSS after loading (the peak is reset through /proc/self/clear_refs before
each run).

"Ours" is, with --ours checkout (the default), the scatter_cli package of the
checkout this script lives in: the repository root is put first on PYTHONPATH
for every child and command, and ours is skipped unless scatter_cli (and, for
the CLI rows, scatter_cli.cli) load from this checkout. With --ours installed it
is whatever scatter_cli the interpreter imports from a neutral directory. Every
peer, and ours, is optional: when it is missing its rows are skipped with a note.

Writes results.json and results.md into --out (default: bench-out/ in the repo)
and prints the Markdown to stdout.
"""

import argparse
import datetime
import json
import math
import os
import shlex
import sys
import tempfile
from pathlib import Path

import numpy as np

from harness import (OURS_MODE_VAR, REPO, child_main, log, make_icosphere, mesh_info,  # noqa: E402
                     real_mesh_path, run_child, spacing_stats, time_command)
from peers import (POISSON_METHODS, UNIFORM_METHODS, cloudcompare_cmd, cloudcompare_env, detect_tools,  # noqa: E402
                   find_scatter, trimesh_script)
from report import machine_summary, markdown_report  # noqa: E402

CONFIGS = {
    "full": {
        "ico_subdivisions": 8,  # 1,310,720 faces
        "uniform_counts": [1_000_000, 10_000_000],
        "repeats": 3,
        "run_budget_s": 90,  # fewer timed runs when one run is slower than budget/repeats
        "e2e_small": 1_000,
        "e2e_big": 10_000_000,
        "e2e_repeats": 5,
        "poisson_ico_counts": [100_000],
        "poisson_real_counts": [10_000, 100_000],
        "cc_poisson_points": 1_000_000,
        "cc_poisson_step": 0.0094,
    },
    "quick": {
        "ico_subdivisions": 5,  # 20,480 faces
        "uniform_counts": [10_000, 100_000],
        "repeats": 3,
        "run_budget_s": 20,
        "e2e_small": 1_000,
        "e2e_big": 100_000,
        "e2e_repeats": 3,
        "poisson_ico_counts": [10_000],
        "poisson_real_counts": [10_000],
        "cc_poisson_points": 100_000,
        "cc_poisson_step": 0.0094 * math.sqrt(10),  # same rho as the full run at 10x fewer points
    },
}


# ---------------------------------------------------------------------------
# Sections
# ---------------------------------------------------------------------------

def measure_in_children(section, methods, tools, mesh, n, cfg, kw_by_method=None):
    rows = []
    for name, (_, _, _, label) in methods.items():
        row = {"section": section, "mesh": mesh["name"], "n": n, "method": name, "call": label}
        if not tools[name]["ok"]:
            row["skipped"] = tools[name]["note"] or "not installed"
        else:
            spec = {"section": section, "method": name, "mesh": mesh["path"], "n": n,
                    "repeats": cfg["repeats"], "run_budget_s": cfg["run_budget_s"],
                    "area": mesh["area"], "kw": (kw_by_method or {}).get(name, {})}
            row.update(run_child(spec))
        log(f"  {section} {mesh['name']} N={n:,} {name}: {brief(row)}")
        rows.append(row)
    return rows


def brief(row):
    if "skipped" in row:
        return "skipped (" + row["skipped"] + ")"
    if "error" in row:
        return "error: " + row["error"]
    return f"{row['median_s']:.3f} s x{row['runs']}"


def section_uniform(cfg, meshes, tools):
    rows = []
    for mesh in meshes:
        for n in cfg["uniform_counts"]:
            rows += measure_in_children("uniform", UNIFORM_METHODS, tools, mesh, n, cfg)
    return rows


def section_e2e(cfg, small, big, tools, tmp):
    rows = []
    py = sys.executable
    repeats = cfg["e2e_repeats"]
    for mesh, n in [(small, cfg["e2e_small"]), (big, cfg["e2e_big"])]:
        out = Path(tmp) / "e2e-out.ply"
        jobs = [
            ("ours", "ours_cli", [find_scatter() or "scatter", "sample", mesh["path"], "-n", str(n),
                                  "-o", str(out)], {"cwd": tmp}),
            ("cloudcompare", "cloudcompare", cloudcompare_cmd(mesh["path"], n, out),
             {"env": cloudcompare_env(tmp), "cwd": tmp}),
            ("trimesh script", "trimesh", [py, "-c", trimesh_script(mesh["path"], n, out)],
             {"cwd": tmp}),
        ]
        for name, tool, cmd, opts in jobs:
            row = {"section": "e2e", "mesh": mesh["name"], "n": n, "method": name,
                   "call": shlex.join(cmd)}
            if tools[tool]["ok"]:
                row.update(time_command(cmd, repeats, out_file=out, **opts))
            else:
                row["skipped"] = tools[tool]["note"] or "not installed"
            log(f"  e2e {mesh['name']} N={n:,} {name}: {brief(row)}")
            rows.append(row)
    for name, code in [("python -c pass", "pass"), ("python -c 'import numpy'", "import numpy"),
                       ("python -c 'import trimesh'", "import trimesh")]:
        cmd = [py, "-c", code]
        row = {"section": "e2e", "mesh": "-", "n": 0, "method": name, "call": shlex.join(cmd)}
        row.update(time_command(cmd, repeats, cwd=tmp))
        log(f"  e2e {name}: {brief(row)}")
        rows.append(row)
    return rows


def section_poisson(cfg, ico, real, tools, tmp):
    """Poisson-disk peers, plus ours (skipped until scatter_cli supports poisson/radius)."""
    rows = []
    for mesh, counts in [(ico, cfg["poisson_ico_counts"]), (real, cfg["poisson_real_counts"])]:
        for n in counts:
            rows += measure_in_children("poisson", POISSON_METHODS, tools, mesh, n, cfg,
                                        kw_by_method={"ours": {"poisson": True}, "ours-numpy": {"poisson": True}})
    step = cfg["cc_poisson_step"]
    rows.append(ours_radius_row(cfg, ico, step, tools))
    rows.append(cloudcompare_poisson_row(cfg, ico, step, tools, tmp))
    rows += ours_poisson_cli_rows(cfg, ico, step, tools, tmp)
    return rows


def ours_radius_row(cfg, mesh, radius, tools):
    """API with radius=R, R the CloudCompare spatial step, so the two compare."""
    row = {"section": "poisson", "mesh": mesh["name"], "n": 0, "method": f"ours radius={radius:.4g}",
           "call": f"scatter_cli.sample(mesh, radius={radius:.4g})"}
    if not tools["ours"]["ok"]:
        row["skipped"] = tools["ours"]["note"]
    else:
        # the child times count=0 plus radius: n is only passed through as count
        spec = {"section": "poisson", "method": "ours", "mesh": mesh["path"], "n": None,
                "repeats": cfg["repeats"], "run_budget_s": cfg["run_budget_s"],
                "area": mesh["area"], "kw": {"radius": radius}}
        row.update(run_child(spec))
    log(f"  poisson {mesh['name']} {row['method']}: {brief(row)}")
    return row


def cloudcompare_poisson_row(cfg, mesh, step, tools, tmp):
    n = cfg["cc_poisson_points"]
    out = Path(tmp) / "cc-poisson.ply"
    cmd = cloudcompare_cmd(mesh["path"], n, out, extra=("-SS", "SPATIAL", f"{step:.6g}"))
    row = {"section": "poisson", "mesh": mesh["name"], "n": n,
           "method": f"cloudcompare SS SPATIAL {step:.4g}", "call": shlex.join(cmd)}
    if not tools["cloudcompare"]["ok"]:
        row["skipped"] = tools["cloudcompare"]["note"]
    else:
        row.update(time_command(cmd, max(1, cfg["repeats"]), out_file=out,
                                env=cloudcompare_env(tmp), cwd=tmp))
        if "error" not in row:
            row.update(spacing_stats(read_ply_points(out), mesh["area"]))
    log(f"  poisson {mesh['name']} {row['method']}: {brief(row)}")
    return row


def ours_poisson_cli_rows(cfg, mesh, step, tools, tmp):
    rows = []
    out = Path(tmp) / "ours-poisson.ply"
    scatter = find_scatter() or "scatter"
    n = cfg["poisson_ico_counts"][0]
    variants = [("ours CLI --poisson", [scatter, "sample", mesh["path"], "--poisson", "-n", str(n),
                                        "-o", str(out)]),
                ("ours CLI --radius", [scatter, "sample", mesh["path"], "--radius", f"{step:.6g}",
                                       "-o", str(out)])]
    for name, cmd in variants:
        row = {"section": "poisson", "mesh": mesh["name"], "n": n if "--poisson" in cmd else 0,
               "method": name, "call": shlex.join(cmd)}
        if not tools["ours_cli"]["ok"]:
            row["skipped"] = tools["ours_cli"]["note"]
        else:
            row.update(time_command(cmd, cfg["repeats"], out_file=out, cwd=tmp))
            if "error" not in row:
                row.update(spacing_stats(read_ply_points(out), mesh["area"]))
        log(f"  poisson {mesh['name']} {name}: {brief(row)}")
        rows.append(row)
    return rows


def read_ply_points(path):
    import trimesh

    return np.asarray(trimesh.load(path).vertices, dtype=np.float64)


# ---------------------------------------------------------------------------
# Main
# ---------------------------------------------------------------------------

def parse_args(argv):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small, fast configuration")
    parser.add_argument("--out", default=str(REPO / "bench-out"), help="directory for JSON + Markdown")
    parser.add_argument("--mesh", default=None,
                        help="real mesh (default samples/skull.ply)")
    parser.add_argument("--ours", choices=["checkout", "installed"], default="checkout",
                        help="measure scatter_cli from this checkout (default) or as installed")
    parser.add_argument("--only", default="uniform,e2e,poisson",
                        help="comma-separated sections to run")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    return parser.parse_args(argv)


def main(argv=None):
    args = parse_args(argv)
    if args.child:
        spec = json.loads(args.child)
        methods = POISSON_METHODS if spec["section"] == "poisson" else UNIFORM_METHODS
        print(json.dumps(child_main(spec, methods)))
        return
    os.environ["NUMPY_MADVISE_HUGEPAGE"] = "0"
    os.environ[OURS_MODE_VAR] = args.ours
    config_name = "quick" if args.quick else "full"
    cfg = CONFIGS[config_name]
    only = set(args.only.split(","))
    out_dir = Path(args.out)
    out_dir.mkdir(parents=True, exist_ok=True)

    tools = detect_tools()
    for name, tool in tools.items():
        log(f"{name}: {'ok' if tool['ok'] else 'MISSING'} {tool.get('version') or ''} "
            f"{tool.get('note') or ''}")

    with tempfile.TemporaryDirectory(prefix="scatter-bench-") as tmp:
        sub = cfg["ico_subdivisions"]
        ico = mesh_info(make_icosphere(tmp, sub, f"icosphere{sub}.ply"))
        ico["name"] = f"icosphere{sub}"
        small = mesh_info(make_icosphere(tmp, 3, "icosphere3.ply"))
        small["name"] = "icosphere3"
        real = mesh_info(real_mesh_path(args.mesh))
        real["name"] = Path(real["path"]).stem
        meshes = [ico, real, small]

        sections = {}
        if "uniform" in only:
            log("== uniform")
            sections["uniform"] = section_uniform(cfg, [ico, real], tools)
        if "e2e" in only:
            log("== e2e")
            sections["e2e"] = section_e2e(cfg, small, ico, tools, tmp)
        if "poisson" in only:
            log("== poisson")
            sections["poisson"] = section_poisson(cfg, ico, real, tools, tmp)

    report = {
        "config_name": config_name,
        "config": cfg,
        "date": datetime.datetime.now().astimezone().isoformat(timespec="seconds"),
        "command": shlex.join(["python", "benchmarks/run.py", *(argv or sys.argv[1:])]),
        "machine": machine_summary(),
        "tools": tools,
        "meshes": meshes,
        "sections": sections,
    }
    (out_dir / "results.json").write_text(json.dumps(report, indent=2) + "\n")
    markdown = markdown_report(report)
    (out_dir / "results.md").write_text(markdown)
    print(markdown)


if __name__ == "__main__":
    main()
