"""``scatter info``: what a mesh file holds, before sampling it."""

from __future__ import annotations

import numpy as np

from .surface import corners, doubled_areas, load_surface


def describe(mesh, input_format=None) -> dict:
    """A JSON-ready summary of ``mesh`` (path, trimesh object or Surface)."""
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
        "geometries": len(surface.geometries),
        "instances": len(surface.instances),
        "objects": [
            {"index": k, "name": inst.name, "geometry": surface.geometries[inst.geometry].name,
             "faces": int(len(surface.geometries[inst.geometry].faces))}
            for k, inst in enumerate(surface.instances)
        ],
    }
    return report


def _attributes(surface) -> dict:
    """Which per-point attributes the file can provide (without computing any of them)."""
    from .visuals import VertexTables

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


def format_text(report) -> str:
    lo, hi = report["bounds"] or [[float("nan")] * 3] * 2
    attrs = [k for k, v in report["attributes"].items() if v]
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
    ]
    if report["instances"] > 1 or report["geometries"] > 1:
        lines += [f"  [{o['index']}] {o['name']} ({o['geometry']}, {o['faces']:,} faces)" for o in report["objects"]]
    return "\n".join(lines)
