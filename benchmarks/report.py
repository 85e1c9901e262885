"""The Markdown report of benchmarks/run.py: tables of the sections' rows."""

import os
import platform

import numpy as np

def fmt_s(seconds):
    if seconds is None:
        return "-"
    return f"{seconds * 1000:.1f} ms" if seconds < 1 else f"{seconds:.2f} s"


def fmt_mb(mb):
    return f"{mb:.0f}" if mb is not None else "-"


def fmt_count(count):
    return f"{count:,}" if count is not None else "-"


def ratio(a, b):
    if a is None or b is None or b == 0:
        return "-"
    return f"{a / b:.2f}x"


def find_row(rows, mesh, n, method):
    for row in rows:
        if row["mesh"] == mesh and row["n"] == n and row["method"] == method and "median_s" in row:
            return row
    return None


def status_cell(row):
    return "skipped: " + row["skipped"] if "skipped" in row else "error: " + row.get("error", "?")


def table(header, rows, cells):
    """Markdown lines: ``header`` (column names), then a row per measurement: its mesh,
    N and method, then ``cells(row)``; a measurement that did not run says why."""
    out = ["| " + " | ".join(header) + " |", "|---|---:|---|" + "---:|" * (len(header) - 3)]
    for row in rows:
        n = f"{row['n']:,}" if row["n"] else "-"
        rest = [status_cell(row)] + [""] * (len(header) - 4) if "median_s" not in row else cells(row)
        out.append("| " + " | ".join([row["mesh"], n, row["method"]] + rest) + " |")
    return out


def uniform_table(rows, meshes):
    mesh_mb = {m["name"]: m["mesh_arrays_mb"] for m in meshes}

    def cells(row):
        ours = find_row(rows, row["mesh"], row["n"], "ours")
        floor = find_row(rows, row["mesh"], row["n"], "floor")
        target = row["n"] * 12 / 2**20 + mesh_mb[row["mesh"]]
        return [fmt_s(row["median_s"]), str(row["runs"]), fmt_s(row["first_s"]),
                ratio(row["median_s"], ours and ours["median_s"]), ratio(row["median_s"], floor and floor["median_s"]),
                f"{row['peak_extra_mb']:.0f}", f"{target:.0f}"]

    return table(["mesh", "N", "method", "median", "runs", "first run", "/ ours", "/ floor", "peak extra MB",
                  "out MB (f32) + mesh MB"], rows, cells)


def e2e_table(rows):
    def cells(row):
        ours = find_row(rows, row["mesh"], row["n"], "ours")
        return [fmt_s(row["median_s"]), str(row["runs"]), ratio(row["median_s"], ours and ours["median_s"]),
                fmt_mb(row["peak_rss_mb"]), fmt_count(row.get("count"))]

    return table(["mesh", "N", "command", "median wall", "runs", "/ ours", "peak RSS MB", "points written"], rows, cells)


def poisson_table(rows):
    def cells(row):
        rho = f"{row['rho']:.3f}" if row.get("rho") is not None else "-"
        if row.get("warning"):
            rho += " (" + row["warning"] + ")"
        return [fmt_s(row["median_s"]), str(row["runs"]), fmt_count(row.get("count")), rho,
                fmt_mb(row.get("peak_extra_mb", row.get("peak_rss_mb")))]

    return table(["mesh", "N asked", "method", "median", "runs", "points returned", "rho", "peak extra MB"], rows, cells)


def markdown_report(report):
    lines = [f"# scatter benchmarks vs peers ({report['config_name']})", "",
             f"- date: {report['date']}",
             f"- command: `{report['command']}`",
             f"- machine: {report['machine']}",
             "- all figures from this one run; medians of back-to-back warm runs after one "
             "warm-up run (\"first run\" is the warm-up)", ""]
    lines += ["## Tools", "", "| tool | available | version | note |", "|---|---|---|---|"]
    for name, tool in report["tools"].items():
        lines.append(f"| {name} | {'yes' if tool['ok'] else 'no'} | {tool.get('version') or '-'} "
                     f"| {tool.get('note') or ''} |")
    lines += ["", "## Meshes", "", "| name | faces | vertices | area | mesh arrays MB | path |",
              "|---|---:|---:|---:|---:|---|"]
    for m in report["meshes"]:
        lines.append(f"| {m['name']} | {m['faces']:,} | {m['vertices']:,} | {m['area']:.4g} "
                     f"| {m['mesh_arrays_mb']:.1f} | {m['path']} |")
    sections = report["sections"]
    if "uniform" in sections:
        lines += ["", "## a. Uniform sampling, in-process (mesh loaded once, not timed)", "",
                  "Times to get an (N, 3) array. `/ ours` and `/ floor`: this method's median "
                  "divided by ours / the floor (above 1 = slower). Peak extra MB: peak RSS during "
                  "a run minus RSS after loading, max over runs. Last column: the memory target, "
                  "an (N, 3) float32 output plus the mesh's vertex and face arrays.", ""]
        lines += uniform_table(sections["uniform"], report["meshes"])
    if "e2e" in sections:
        lines += ["", "## b. End to end, whole commands (wall time)", "",
                  "Output written to a temp dir; `points written` read back from the PLY header.",
                  ""]
        lines += e2e_table(sections["e2e"])
    if "poisson" in sections:
        lines += ["", "## c. Poisson-disk sampling", "",
                  "rho = d_min / sqrt(2A / (sqrt(3) N)), N = points returned, A = mesh area "
                  "(1 = hexagonal packing). CloudCompare and CLI rows are whole commands "
                  "(wall time, peak RSS of the process).", ""]
        lines += poisson_table(sections["poisson"])
    lines += ["", "## Calls", ""]
    seen = set()
    for rows in sections.values():
        for row in rows:
            key = (row["section"], row["method"], row["call"] if row["section"] != "e2e" else "")
            if row["section"] != "e2e" and key not in seen:
                seen.add(key)
                lines.append(f"- {row['section']} / {row['method']}: `{row['call']}`")
    for row in sections.get("e2e", []):
        lines.append(f"- e2e / {row['method']} N={row['n']}: `{row['call']}`")
    return "\n".join(lines) + "\n"


def machine_summary():
    return (f"{os.cpu_count()} cores, {platform.machine()}, Python {platform.python_version()}, "
            f"numpy {np.__version__}")
