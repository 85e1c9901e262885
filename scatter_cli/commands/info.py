"""``scatter info``: what a mesh file holds, before sampling it."""

from __future__ import annotations

import numpy as np

from ..loading.load import load_surface
from ..surface.model import corners, doubled_areas
from ..sampling.sharp import SHARP_ANGLE
from ..surface.topology import edges


def describe(mesh, input_format=None, exterior=False, sharp_angle=None) -> dict:
    """A JSON-ready summary of ``mesh`` (path, trimesh object or Surface); ``exterior``
    adds :func:`exterior_report`; its sharp edges at ``sharp_angle`` degrees (default 15)."""
    surface = load_surface(mesh, input_format=input_format)
    areas, finite, lo, hi = [], [], np.full(3, np.inf), np.full(3, -np.inf)
    for inst in surface.instances:
        g = surface.geometries[inst.geometry]
        with np.errstate(all="ignore"):
            a = 0.5 * doubled_areas(corners(g.vertices, g.faces), inst.matrix)
        ok = np.isfinite(g.vertices).all(axis=1)[g.faces].all(axis=1)
        areas.append(a)
        finite.append(ok)
        used = surface.world_vertices(inst)[np.unique(g.faces[ok])]
        if len(used):
            lo, hi = np.minimum(lo, used.min(axis=0)), np.maximum(hi, used.max(axis=0))
    areas, finite = np.concatenate(areas), np.concatenate(finite)
    good = finite & np.isfinite(areas)
    positive = areas[good & (areas > 0)]
    closed = closedness(surface, np.where(good, areas, 0.0))
    report = {
        "file": surface.source,
        "faces": int(len(areas)),
        "vertices": int(sum(len(surface.geometries[i.geometry].vertices) for i in surface.instances)),
        "area": float(positive.sum()),
        "bounds": [lo.tolist(), hi.tolist()] if np.isfinite(lo).all() else None,
        "zero_area_faces": int(np.sum(good & (areas == 0))),
        "non_finite_faces": int(np.sum(~good)),
        "area_ratio": float(positive.max() / positive.min()) if len(positive) else None,
        "attributes": _attributes(surface),
        "needs_pillow": _unread_texture(surface),
        "geometries": len(surface.geometries),
        "instances": len(surface.instances),
        "objects": [
            {"index": k, "name": inst.name, "geometry": surface.geometries[inst.geometry].name,
             "faces": int(len(surface.geometries[inst.geometry].faces))}
            for k, inst in enumerate(surface.instances)
        ],
    }
    report.update(closed)
    report["unclear_inside"] = None if closed["closed"] or not len(positive) else unclear_inside(surface, lo, hi)
    report["sharp_edges"] = sharp_report(surface, report["objects"], SHARP_ANGLE if sharp_angle is None else sharp_angle)
    report["unsampled"] = [{"path": u.path, "reason": u.reason, "area": u.area} for u in surface.unsampled]
    if exterior:
        report["exterior"] = exterior_report(surface)
    return report


def closedness(surface, areas) -> dict:
    """Whether every geometry the surface places is closed (topology.py), and else its
    boundary, non-manifold and inconsistently oriented edges and the area (world space,
    ``areas`` (F,) per face of every instance in order) of the faces at the boundary;
    instances counted."""
    found = {}
    counts = np.zeros(3, np.int64)
    at_boundary = []
    for inst in surface.instances:
        if inst.geometry not in found:
            g = surface.geometries[inst.geometry]
            found[inst.geometry] = edges(g.vertices, g.faces)
        e = found[inst.geometry]
        counts += (e.boundary, e.non_manifold, e.inconsistent)
        at_boundary.append(e.at_boundary)
    boundary_area = float(areas[np.concatenate(at_boundary)].sum()) if at_boundary else 0.0
    return {"closed": bool(not counts.any()), "boundary_edges": int(counts[0]), "non_manifold_edges": int(counts[1]),
            "inconsistent_edges": int(counts[2]), "boundary_area": boundary_area}


# The probe run behind ``unclear_inside``: its points, half of them uniform in the box a
# --volume run samples and half near the surface, at a deviation of SIGN_SIGMA times the
# bounding box's diagonal (standard error of the share at most 0.5 / sqrt(SIGN_PROBES));
# a surface is much open when more than OPEN_SHARE of them have no clear side.
SIGN_PROBES = 10_000
SIGN_SIGMA = 0.01
OPEN_SHARE = 0.05


def unclear_inside(surface, lo, hi) -> float:
    """The share of the points around ``surface`` (its bounding box ``lo``, ``hi`` (3,))
    whose inside or outside is close to a coin flip: their winding numbers within
    :data:`~scatter_cli.volume.signs.NEAR_HALF` of 1/2 (see SIGN_PROBES)."""
    from ..api import prepare
    from ..volume.signs import unclear

    sigma = SIGN_SIGMA * float(np.linalg.norm(hi - lo))
    run = prepare(surface, SIGN_PROBES, near=(sigma,), box_share=0.5, attributes=("winding",), precision="float64")
    return float(np.mean(unclear(run.collect().winding)))


def sharp_report(surface, objects, angle) -> dict:
    """The sharp edges at ``angle`` degrees (:mod:`scatter_cli.sampling.sharp`) in total,
    {angle, count, length} (world-space length), and the same in each record of
    ``objects`` (one per instance, in order), in place."""
    from ..sampling.edges import EdgeTable

    table = EdgeTable(surface, angle)
    count = np.bincount(table.instance, minlength=len(objects))
    length = np.bincount(table.instance, weights=table.length, minlength=len(objects))
    for k, record in enumerate(objects):
        record["sharp_edges"] = {"angle": float(angle), "count": int(count[k]), "length": float(length[k])}
    return {"angle": float(angle), "count": len(table), "length": table.total_length}


# Uniform candidates behind the exterior-area estimate of ``scatter info --exterior``
# (standard error at most 0.5 / sqrt(N) of the area), and the probes of each face.
INFO_CANDIDATES = 100_000
FACE_PROBES = np.array([[0.8, 0.1, 0.1], [0.1, 0.8, 0.1], [0.1, 0.1, 0.8], [1 / 3, 1 / 3, 1 / 3]])


def exterior_report(surface, seed=0) -> dict:
    """Exterior area (estimate from uniform candidates, with its standard error) and the
    faces whose probes (three points near the corners and the centroid) are all, some or
    none exterior. The face counts are a survey, not a certificate: a face partly hidden
    between its probes counts as exterior (so sampling classifies every point it keeps)."""
    from ..sampling.exterior.filter import ExteriorSource, classify
    from ..sampling.plan import RawChunk, SamplePlan
    from ..sampling.exterior.rays import Occluder

    occluder = Occluder(surface)
    plan = SamplePlan(surface)
    source = ExteriorSource(_Plain(plan, seed), occluder, seed, plan.area, candidates=INFO_CANDIDATES)
    seen = []
    for k, inst in enumerate(surface.instances):
        g = surface.geometries[inst.geometry]
        tri = surface.world_vertices(inst)[g.faces]  # (F, 3, 3)
        points = np.einsum("pk,fkc->fpc", FACE_PROBES, tri).reshape(-1, 3)
        face = np.repeat(np.arange(len(g.faces)), len(FACE_PROBES))
        chunk = RawChunk(0, points, face, np.full(len(face), k, np.int64), None)
        with np.errstate(invalid="ignore"):
            ok, _ = classify(occluder, chunk, seed) if len(face) else (np.zeros(0, bool), 0)
        seen.append(ok.reshape(-1, len(FACE_PROBES)).sum(axis=1))
    seen = np.concatenate(seen) if seen else np.zeros(0, np.int64)
    st = source.stats
    return {
        "area": st["exterior_area"],
        "area_se": st["exterior_area_se"],
        "fraction": st["exterior_fraction"],
        "candidates": st["candidates"],
        "faces_exterior": int(np.sum(seen == len(FACE_PROBES))),
        "faces_mixed": int(np.sum((seen > 0) & (seen < len(FACE_PROBES)))),
        "faces_hidden": int(np.sum(seen == 0)),
        "faces_enclosed": occluder.enclose() if st["exterior_candidates"] < st["candidates"] else 0,
    }


class _Plain:
    """The random stream of ``plan`` as a source."""

    def __init__(self, plan, seed):
        self.plan, self.seed = plan, seed

    def draw(self, start, stop):
        return self.plan.draw(start, stop, self.seed)


def _attributes(surface) -> dict:
    """Which per-point attributes the file can provide (without computing any of them)."""
    from ..surface.data import VertexTables

    has = {"normals": False, "colors": False, "uv": False, "texture": False}
    for g in surface.geometries:
        mesh = g.mesh
        if mesh is None:
            continue
        if isinstance(mesh, VertexTables):
            has["normals"] |= mesh.normals is not None
            has["colors"] |= any(c is not None for c in (mesh.vertex_colors, mesh.face_colors, mesh.constant_color))
            has["uv"] |= mesh.uv is not None
            continue
        cache = getattr(mesh, "_cache", None)
        if cache is not None and "vertex_normals" in getattr(cache, "cache", {}):
            has["normals"] = True
        visual = getattr(mesh, "visual", None)
        kind = getattr(visual, "kind", None)
        if kind == "vertex":
            has["colors"] = True
        if kind == "texture":
            uv = getattr(visual, "uv", None)
            has["uv"] = has["uv"] or (uv is not None and len(uv) > 0)
            material = getattr(visual, "material", None)
            image = getattr(material, "image", None) or getattr(material, "baseColorTexture", None)
            has["texture"] = has["texture"] or image is not None
    return has


def _unread_texture(surface) -> bool:
    """Whether the file names a texture that could not be read for want of Pillow."""
    from ..loading.textures import named_textures, pillow_missing

    return pillow_missing() and bool(named_textures(surface.source))


def format_text(report) -> str:
    lo, hi = report["bounds"] or [[float("nan")] * 3] * 2
    attrs = [k for k, v in report["attributes"].items() if v]
    if report["needs_pillow"]:
        from ..loading.textures import INSTALL

        attrs = [a for a in attrs if a != "texture"] + [f"texture (reading it needs Pillow: {INSTALL})"]
    lines = [
        f"file           {report['file']}",
        f"faces          {report['faces']:,}",
        f"vertices       {report['vertices']:,}",
        f"surface area   {report['area']:.9g}",
        f"bounding box   [{', '.join(f'{x:.6g}' for x in lo)}] .. [{', '.join(f'{x:.6g}' for x in hi)}]",
        f"zero-area      {report['zero_area_faces']:,} faces",
        f"non-finite     {report['non_finite_faces']:,} faces",
        f"area ratio     {report['area_ratio']:.3g} (largest / smallest non-zero face)"
        if report["area_ratio"] else "area ratio     -",
        f"attributes     {', '.join(attrs) or 'none'}",
        f"objects        {report['instances']} instance(s) of {report['geometries']} geometry(ies)",
        _closed_line(report),
        *_inside_line(report),
        _sharp_line(report["sharp_edges"], "sharp edges    "),
    ]
    for u in report["unsampled"]:
        area = f", area {u['area']:.6g}" if u["area"] else ""
        lines.append(f"not sampled    {u['path']} ({u['reason']}{area})")
    ext = report.get("exterior")
    if ext:
        lines += [
            f"exterior area  {ext['area']:.6g} ± {ext['area_se']:.2g} ({100 * ext['fraction']:.2f} %, "
            f"from {ext['candidates']:,} uniform points)",
            f"exterior faces {ext['faces_exterior']:,} all probes out, {ext['faces_mixed']:,} some, "
            f"{ext['faces_hidden']:,} none (4 probes a face); {ext['faces_enclosed']:,} enclosed in a closed shell",
        ]
    if report["instances"] > 1 or report["geometries"] > 1:
        lines += [f"  [{o['index']}] {o['name']} ({o['geometry']}, {o['faces']:,} faces; "
                  f"{_sharp_line(o['sharp_edges'])})" for o in report["objects"]]
    return "\n".join(lines)


def _sharp_line(sharp, label="") -> str:
    """``N sharp edges at A degrees, length L`` (what --edges would draw points on)."""
    return f"{label}{sharp['count']:,} at {sharp['angle']:g} degrees, length {sharp['length']:.6g}" if label else (
        f"{sharp['count']:,} sharp edges, length {sharp['length']:.6g}")


def _closed_line(report) -> str:
    if report["closed"]:
        return "closed         yes (every edge shared by two faces, consistently oriented): both --sign modes hold"
    share = report["boundary_area"] / report["area"] if report["area"] else 0.0
    return (f"closed         no: {report['boundary_edges']:,} boundary, {report['non_manifold_edges']:,} non-manifold, "
            f"{report['inconsistent_edges']:,} inconsistently oriented edges; {report['boundary_area']:.6g} of the "
            f"area ({100 * share:.3g} %) on faces at the boundary")


def _inside_line(report) -> list:
    """How far an open surface has an inside, and which --sign to trust (none when much of it is open)."""
    share = report["unclear_inside"]
    if share is None:
        return []
    from ..volume.signs import NEAR_HALF, percent

    verdict = ("much of it is open, as a terrain or a sheet is: no --sign mode gives inside a meaning"
               if share > OPEN_SHARE else "--sign winding is the one to trust")
    return [f"inside         unclear at {percent(share)} of the points around it (winding number within {NEAR_HALF:g} "
            f"of 0.5): {verdict}"]
