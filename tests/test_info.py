"""`scatter info`: whether a surface is closed, and else its boundary, non-manifold and
inconsistently oriented edges and the area at the boundary, against a plain reference
(a dictionary of edges, one face at a time) on the samples and on broken variants."""

import json
from collections import defaultdict

import numpy as np
import pytest

from scatter_cli.commands import info
from scatter_cli.surface import topology
from scatter_cli.loading.load import load_surface
from scatter_cli.surface.model import Geometry, Instance, Surface, corners, doubled_areas

from .conftest import SAMPLES, run_scatter, scatter_in_process

SAMPLES_CLOSED = {"icosahedron_binary.stl": True, "hemisphere.off": False, "moebius-160-10.ply": False,
                  "pediment_join_plate_12.stl": False}


def reference(vertices, faces):
    """(boundary, non-manifold, inconsistent edges, (F,) faces at the boundary), one edge
    at a time in a dictionary keyed by the corners' positions."""
    key = [tuple(map(float, v)) for v in vertices + 0.0]
    uses = defaultdict(list)  # edge -> [(face, runs from the smaller key to the larger)]
    for k, face in enumerate(faces.tolist()):
        for a, b in zip(face, face[1:] + face[:1]):
            if key[a] != key[b]:
                uses[frozenset((key[a], key[b]))].append((k, key[a] < key[b]))
    boundary = [e for e, u in uses.items() if len(u) == 1]
    at = np.zeros(len(faces), bool)
    for e in boundary:
        at[uses[e][0][0]] = True
    inconsistent = sum(1 for u in uses.values() if len(u) == 2 and u[0][1] == u[1][1])
    return len(boundary), sum(1 for u in uses.values() if len(u) > 2), inconsistent, at


def assert_matches_reference(vertices, faces):
    e = topology.edges(vertices, faces)
    b, n, i, at = reference(vertices, faces)
    assert (e.boundary, e.non_manifold, e.inconsistent) == (b, n, i)
    assert np.array_equal(e.at_boundary, at)
    assert e.closed == (b == n == i == 0)
    return e


def geometry(name):
    surface = load_surface(str(SAMPLES / name))
    assert len(surface.geometries) == 1
    return surface.geometries[0]


@pytest.mark.parametrize("name", sorted(SAMPLES_CLOSED))
def test_the_samples_match_the_reference(name):
    g = geometry(name)
    e = assert_matches_reference(g.vertices, g.faces)
    assert e.closed == SAMPLES_CLOSED[name]


def test_each_sample_shows_its_defect():
    """The open one has boundary edges only, the Moebius strip inconsistent edges too,
    the 3D-printing file non-manifold edges (Thingi10K counts 7)."""
    hemi = topology.edges(geometry("hemisphere.off").vertices, geometry("hemisphere.off").faces)
    assert hemi.boundary > 0 and hemi.non_manifold == hemi.inconsistent == 0
    g = geometry("moebius-160-10.ply")
    moebius = topology.edges(g.vertices, g.faces)
    assert moebius.boundary > 0 and moebius.inconsistent > 0
    g = geometry("pediment_join_plate_12.stl")
    assert topology.edges(g.vertices, g.faces).non_manifold == 7


def broken(kind):
    """The closed icosahedron, broken: a face removed, a face flipped, a face doubled."""
    g = geometry("icosahedron_binary.stl")
    f = g.faces.copy()
    if kind == "hole":
        f = f[1:]
    elif kind == "flipped":
        f[0] = f[0, [0, 2, 1]]
    elif kind == "doubled":
        f = np.vstack([f, f[:1]])
    return g.vertices, f


@pytest.mark.parametrize("kind,expected", [("hole", (3, 0, 0)), ("flipped", (0, 0, 3)), ("doubled", (0, 3, 0))])
def test_a_broken_icosahedron_is_not_closed(kind, expected):
    vertices, faces = broken(kind)
    e = assert_matches_reference(vertices, faces)
    assert not e.closed and (e.boundary, e.non_manifold, e.inconsistent) == expected
    assert e.at_boundary.sum() == (3 if kind == "hole" else 0)  # the hole's three neighbours


def test_the_vertices_are_welded_by_position():
    """The binary STL repeats every corner: unwelded, every edge would be a boundary."""
    g = geometry("icosahedron_binary.stl")
    assert len(g.vertices) == 3 * len(g.faces)
    assert topology.edges(g.vertices, g.faces).closed
    shifted = g.vertices.copy()
    shifted[0] += 1e-12  # one corner no longer on its neighbours' corner
    e = assert_matches_reference(shifted, g.faces)
    assert not e.closed and e.boundary == 4  # the moved corner's two edges, and their two neighbours' 


def test_a_scene_counts_every_instance_and_its_area():
    vertices, faces = broken("hole")
    scale = np.diag([2.0, 2.0, 2.0, 1.0])
    surface = Surface([Geometry("ico", vertices, faces)], [Instance("a", 0), Instance("b", 0, scale)], "s", True)
    report = info.describe(surface)
    assert report["boundary_edges"] == 6 and not report["closed"]
    at = topology.edges(vertices, faces).at_boundary
    area = 0.5 * doubled_areas(corners(vertices, faces))[at].sum()
    assert report["boundary_area"] == pytest.approx(5 * area, rel=1e-12)  # 1 + 2 squared


@pytest.mark.slow
def test_info_says_it_in_text_and_json(tmp_path):
    closed = json.loads(run_scatter("info", SAMPLES / "icosahedron_binary.stl", "--json", check=True).stdout)
    assert closed["closed"] and closed["boundary_edges"] == closed["non_manifold_edges"] == 0
    # (the rest through the command's entry point in this process)
    report = json.loads(scatter_in_process("info", SAMPLES / "hemisphere.off", "--json", check=True).stdout)
    g = geometry("hemisphere.off")
    b, n, i, at = reference(g.vertices, g.faces)
    assert (report["closed"], report["boundary_edges"], report["non_manifold_edges"], report["inconsistent_edges"]) == (
        False, b, n, i)
    assert report["boundary_area"] == pytest.approx(0.5 * doubled_areas(corners(g.vertices, g.faces))[at].sum())
    text = scatter_in_process("info", SAMPLES / "hemisphere.off", check=True).stdout.decode()
    line = [s for s in text.splitlines() if s.startswith("closed")]
    assert len(line) == 1 and line[0].split()[1] == "no:" and f"{b:,} boundary" in line[0]
    text = scatter_in_process("info", SAMPLES / "icosahedron_binary.stl", check=True).stdout.decode()
    assert [s.split()[1] for s in text.splitlines() if s.startswith("closed")] == ["yes"]
