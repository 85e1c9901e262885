"""Attributes (normal, smooth-normal, uv, color) and density weighting.

Statistical tests use fixed seeds and significance level ALPHA; each has a paired
must-fail case showing that the test would catch the mistake it guards against.
"""

import numpy as np
import pytest
import trimesh

import scatter_cli
from scatter_cli.run.attributes import AttributeMaker
from scatter_cli.errors import ScatterError, ScatterUsageError
from scatter_cli.sampling.plan import RawChunk
from scatter_cli.loading.load import load_surface
from scatter_cli.surface.model import Geometry
from scatter_cli.surface.texture import CLAMP_TO_EDGE, MIRRORED_REPEAT, REPEAT, bilinear, wrap_index
from scatter_cli.surface.data import vertex_normal_table
from scatter_cli.sampling.weighting import barycentric
from scatter_cli.stats.chisquare import chi2_gof

from .conftest import SAMPLES, run_scatter, scaled_scene

ALPHA = 1e-3
PIL = pytest.importorskip("PIL.Image")


def chi_p(counts, expect):
    """Chi-square p-value of ``counts`` against ``expect`` (rescaled to the same total);
    a count where nothing is expected gives p = 0."""
    counts, expect = np.asarray(counts, float), np.asarray(expect, float)
    if np.any(counts[expect <= 0] > 0):
        return 0.0
    keep = expect > 0
    return chi2_gof(counts[keep], expect[keep])[2]


def attributes_at(mesh, face, bary, names):
    """Our attributes at given (face (n,), bary (n, 3)) of a single mesh."""
    surface = load_surface(mesh)
    maker = AttributeMaker(surface, names)
    raw = RawChunk(0, None, np.asarray(face, np.int64), np.zeros(len(face), np.int64), np.asarray(bary, float))
    return maker.make(raw, np.float64)


def trimesh_samples(mesh, n, seed=0):
    pts, face, colors, bary = trimesh.sample.sample_surface(mesh, n, sample_color=True, return_barycentric=True, seed=seed)
    return pts, face, colors, bary


def textured_quad(pixels, uv_scale=1.0):
    """A unit square in z=0 (two triangles) with uv = (x, y) * uv_scale and the given RGBA texture."""
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    f = np.array([[0, 1, 2], [0, 2, 3]])
    visual = trimesh.visual.TextureVisuals(uv=v[:, :2] * uv_scale, image=PIL.fromarray(np.asarray(pixels, np.uint8)))
    return trimesh.Trimesh(v, f, visual=visual, process=False)


# -- normals ---------------------------------------------------------------------------

def test_normals_unit_length_and_match_the_face():
    mesh = trimesh.load(SAMPLES / "spot_triangulated.obj", process=False)
    s = scatter_cli.sample(mesh, 5000, attributes=("normal", "face"), precision="float64", seed=1)
    np.testing.assert_allclose(np.linalg.norm(s.normal, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(s.normal, mesh.face_normals[s.face], atol=1e-9)


def test_normals_in_a_scene_follow_non_uniform_scale():
    scene = scaled_scene()
    flat = scene.to_mesh()
    s = scatter_cli.sample(scene, 3000, attributes=("normal", "object", "face"), precision="float64", seed=2)
    np.testing.assert_allclose(np.linalg.norm(s.normal, axis=1), 1.0, atol=1e-12)
    # The flattened mesh stacks the instances' faces in instance order.
    offset = np.cumsum([0] + [len(scene.geometry[scene.graph[n][1]].faces) for n in scene.graph.nodes_geometry])
    np.testing.assert_allclose(s.normal, flat.face_normals[offset[s.object] + s.face], atol=1e-9)
    # Must-fail: rotating the normals with the matrix itself (not its cofactor) is wrong under non-uniform scale.
    m = scene.graph[scene.graph.nodes_geometry[1]][0][:3, :3]
    sel = s.object == 1
    local = scene.geometry[scene.graph[scene.graph.nodes_geometry[1]][1]].face_normals[s.face[sel]]
    wrong = local @ m.T
    wrong /= np.linalg.norm(wrong, axis=1, keepdims=True)
    assert np.abs(wrong - s.normal[sel]).max() > 0.1


def test_smooth_normals_unit_and_closer_to_the_sphere_than_face_normals():
    sphere = trimesh.creation.icosphere(subdivisions=2)
    s = scatter_cli.sample(sphere, 5000, attributes=("smooth-normal",), precision="float64", seed=3)
    np.testing.assert_allclose(np.linalg.norm(s.normal, axis=1), 1.0, atol=1e-12)
    radial = s.points / np.linalg.norm(s.points, axis=1, keepdims=True)
    f = scatter_cli.sample(sphere, 5000, attributes=("normal",), precision="float64", seed=3)
    assert np.abs(1 - (s.normal * radial).sum(1)).mean() < 0.2 * np.abs(1 - (f.normal * radial).sum(1)).mean()


def test_smooth_normals_use_the_file_normals():
    mesh = trimesh.load(SAMPLES / "cesiummilktruck.glb", process=False)
    g = mesh.geometry["Wheels"]
    face = np.arange(len(g.faces))
    bary = np.full((len(face), 3), 1 / 3)
    got = attributes_at(g, face, bary, ("smooth-normal",))["normal"]
    want = g.vertex_normals[g.faces].mean(axis=1)
    want /= np.linalg.norm(want, axis=1, keepdims=True)
    np.testing.assert_allclose(got, want, atol=1e-9)


@pytest.mark.slow
def test_computed_vertex_normals_are_trimeshs(monkeypatch):
    # Without file normals, smooth normals come from our own array code: trimesh's needs
    # SciPy, which the command line hides, and its fallback is quadratic in the vertex count.
    mesh = trimesh.load(SAMPLES / "skull.ply", process=False)
    want = np.array(mesh.vertex_normals)  # trimesh's, through SciPy here
    fresh = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    monkeypatch.setattr(trimesh.geometry, "weighted_vertex_normals",
                        lambda *a, **k: pytest.fail("trimesh's vertex normals were computed"))
    np.testing.assert_allclose(vertex_normal_table(Geometry("fresh", fresh.vertices, fresh.faces, fresh)), want, atol=1e-12)
    # the file's own normals win over computed ones
    flipped = trimesh.Trimesh(mesh.vertices, mesh.faces, vertex_normals=-want, process=False)
    np.testing.assert_allclose(vertex_normal_table(Geometry("flipped", flipped.vertices, flipped.faces, flipped)), -want, atol=1e-12)


def test_normal_and_smooth_normal_together_is_a_usage_error():
    with pytest.raises(ScatterUsageError):
        scatter_cli.sample(SAMPLES / "spot_triangulated.obj", 10, attributes=("normal", "smooth-normal"))


# -- uv and colour against trimesh and pymeshlab -----------------------------------------

def test_uv_matches_trimesh_interpolation_at_the_same_points():
    mesh = trimesh.load(SAMPLES / "spot_triangulated.obj", process=False)
    _, face, _, bary = trimesh_samples(mesh, 4000)
    got = attributes_at(mesh, face, bary, ("uv",))["uv"]
    want = np.einsum("ij,ijk->ik", bary, mesh.visual.uv[mesh.faces[face]])
    np.testing.assert_allclose(got, want, atol=1e-12)


def test_vertex_colours_average_to_trimesh_face_colours():
    # trimesh's sample_color gives each point its face's colour (the mean of its
    # vertex colours); our interpolated colours must average to it over each face.
    mesh = trimesh.load(SAMPLES / "boxvertexcolors.glb", process=False).to_mesh()
    _, face, colors, bary = trimesh_samples(mesh, 60_000, seed=4)
    got = attributes_at(mesh, face, bary, ("color",))["color"].astype(float)
    for f in range(len(mesh.faces)):
        sel = face == f
        se = got[sel].std(axis=0) / np.sqrt(sel.sum()) + 0.5
        assert np.all(np.abs(got[sel].mean(axis=0) - colors[sel].astype(float).mean(axis=0)) < 5 * se)
    # Must-fail: the first corner's colour (no interpolation) does not average to it.
    # (Nearest-corner colours would pass: each corner's region holds a third of the face.)
    nearest = mesh.visual.vertex_colors[mesh.faces[face, 0]].astype(float)
    failed = 0
    for f in range(len(mesh.faces)):
        sel = face == f
        se = nearest[sel].std(axis=0) / np.sqrt(sel.sum()) + 0.5
        failed += np.any(np.abs(nearest[sel].mean(axis=0) - colors[sel].astype(float).mean(axis=0)) >= 5 * se)
    assert failed > 0


def test_vertex_colours_match_pymeshlab_attribute_transfer():
    pymeshlab = pytest.importorskip("pymeshlab")
    path = SAMPLES / "boxvertexcolors.glb"
    s = scatter_cli.sample(path, 3000, attributes=("color",), precision="float64", seed=5)
    ms = pymeshlab.MeshSet()
    ms.load_new_mesh(str(path))
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=s.points))
    ms.transfer_attributes_per_vertex(sourcemesh=0, targetmesh=1, colortransfer=True)
    theirs = np.rint(ms.current_mesh().vertex_color_matrix() * 255)
    # The points lie on the unit box's faces: the nearest face plane at distance 0 ...
    to_planes = np.sort(np.minimum(s.points, 1 - s.points), axis=1)
    assert (s.points >= 0).all() and (s.points <= 1).all() and to_planes[:, 0].max() < 1e-12
    # ... and away from its edges (where two faces are equally close) the colours agree.
    interior = to_planes[:, 1] > 0.01
    assert interior.sum() > 2000
    diff = np.abs(theirs[interior] - s.color[interior].astype(float))
    assert diff.max() <= 2


def test_texture_colours_match_trimesh_on_a_smooth_texture():
    # A smooth texture: trimesh's (W-1)-scaled and our texel-centred bilinear lookups agree
    # to within the half-texel offset times the gradient.
    x = np.arange(64)
    img = np.zeros((64, 64, 4), np.uint8)
    img[..., 0] = (127 + 120 * np.sin(2 * np.pi * x / 64))[None, :]
    img[..., 1] = (127 + 120 * np.cos(2 * np.pi * x / 64))[:, None]
    img[..., 2], img[..., 3] = 50, 255
    mesh = textured_quad(img)
    _, face, colors, bary = trimesh_samples(mesh, 5000, seed=6)
    got = attributes_at(mesh, face, bary, ("color",))["color"].astype(float)
    assert np.abs(got - colors).max() <= 15
    assert np.abs(got - colors).mean() <= 3


def test_texture_colours_on_a_real_glb_close_to_trimesh():
    mesh = trimesh.load(SAMPLES / "boxtextured.glb", process=False).to_mesh()
    ours_first = attributes_at(mesh, [0], [[1 / 3, 1 / 3, 1 / 3]], ("color",))  # before trimesh touches it
    assert ours_first["color"].shape == (1, 4)
    mesh.visual.material = mesh.visual.material.to_simple()  # trimesh's sampler reads material.image
    _, face, colors, bary = trimesh_samples(mesh, 5000, seed=7)
    got = attributes_at(mesh, face, bary, ("color",))["color"].astype(float)
    assert np.median(np.abs(got - colors)) <= 2


def test_bilinear_hits_texel_centres_and_wrap_modes():
    px = np.arange(4 * 2 * 1, dtype=float).reshape(2, 4, 1)  # rows top to bottom
    centres = np.array([[(i + 0.5) / 4, 1 - (j + 0.5) / 2] for j in range(2) for i in range(4)])
    np.testing.assert_allclose(bilinear(px, centres)[:, 0], px.ravel())
    np.testing.assert_array_equal(wrap_index(np.array([-1, 4, 5]), 4, REPEAT), [3, 0, 1])
    np.testing.assert_array_equal(wrap_index(np.array([-1, 4, 5]), 4, CLAMP_TO_EDGE), [0, 3, 3])
    np.testing.assert_array_equal(wrap_index(np.array([-1, 4, 5, 8]), 4, MIRRORED_REPEAT), [0, 3, 2, 0])
    # REPEAT: the left border blends the first and the last column half and half.
    np.testing.assert_allclose(bilinear(px, [[0.0, 0.75]])[:, 0], [(0 + 3) / 2])


@pytest.mark.slow
def test_attributes_the_file_cannot_provide_are_clear_errors(tmp_path):
    with pytest.raises(ScatterError, match=r"koala\.obj.*'uv'"):
        scatter_cli.sample(SAMPLES / "koala.obj", 10, attributes=("uv",))
    with pytest.raises(ScatterError, match=r"spot_triangulated\.obj.*'color'"):
        scatter_cli.sample(SAMPLES / "spot_triangulated.obj", 10, attributes=("color",))
    proc = run_scatter("sample", SAMPLES / "koala.obj", "-n", "5", "-a", "uv", "-o", tmp_path / "o.csv")
    assert proc.returncode == 1 and b"uv" in proc.stderr and b"koala.obj" in proc.stderr
    assert not (tmp_path / "o.csv").exists()


# -- density weighting --------------------------------------------------------------------

def subtriangles(level):
    """Barycentric corners of the 4**level congruent sub-triangles of the reference triangle: (m, 3, 3)."""
    tris = [np.eye(3)]
    for _ in range(level):
        nxt = []
        for t in tris:
            a, b, c = t
            ab, bc, ca = (a + b) / 2, (b + c) / 2, (c + a) / 2
            nxt += [np.array([a, ab, ca]), np.array([ab, b, bc]), np.array([ca, bc, c]), np.array([ab, bc, ca])]
        tris = nxt
    return np.array(tris)


def locate(bary, subs):
    """Index of the sub-triangle containing each barycentric point."""
    out = np.full(len(bary), -1)
    for j, t in enumerate(subs):
        lam = np.linalg.solve(t.T, bary.T).T
        out[(lam >= -1e-12).all(axis=1) & (out < 0)] = j
    return out


def colour_grid(seed=0, zero_face=None):
    rng = np.random.default_rng(seed)
    tri = rng.random((30, 3, 3)) * [4, 4, 0.2]
    mesh = trimesh.Trimesh(tri.reshape(-1, 3), np.arange(90).reshape(-1, 3), process=False)
    colors = rng.integers(0, 256, (90, 4), dtype=np.uint8)
    if zero_face is not None:
        colors[3 * zero_face : 3 * zero_face + 3, 0] = 0
    mesh.visual = trimesh.visual.ColorVisuals(mesh, vertex_colors=colors)
    return mesh


def test_vertex_colour_weight_chi_square_against_area_times_exact_mean_weight():
    mesh = colour_grid(zero_face=7)
    n = 60_000
    w = mesh.visual.vertex_colors[:, 0][mesh.faces] / 255.0
    expect = mesh.area_faces * w.mean(axis=1)
    expect = expect / expect.sum() * n
    s = scatter_cli.sample(mesh, n, weight="vertex-color:r", attributes=("face", "bary"), seed=8)
    counts = np.bincount(s.face, minlength=len(mesh.faces))
    assert counts[7] == 0  # a zero-weight face gets no points
    assert chi_p(counts, expect) > ALPHA
    # Must-fail: ignoring the weight.
    u = scatter_cli.sample(mesh, n, attributes=("face",), seed=8)
    assert chi_p(np.bincount(u.face, minlength=30), expect) < ALPHA


@pytest.mark.slow
def test_vertex_colour_weight_is_exact_inside_a_face():
    # Density w0 b0 + w1 b1 + w2 b2 on one triangle: sub-triangle masses are exact
    # (area times the weight at its centroid, as the weight is linear).
    rng = np.random.default_rng(1)
    w = np.array([0.9, 0.05, 0.3])
    u = rng.random((80_000, 3))
    b12 = barycentric(np.tile(w, (len(u), 1)), u)
    bary = np.column_stack([1 - b12.sum(1), b12])
    subs = subtriangles(2)
    expect = subs.mean(axis=1) @ w
    expect = expect / expect.sum() * len(u)
    counts = np.bincount(locate(bary, subs), minlength=len(subs))
    assert chi2_gof(counts, expect)[2] > ALPHA
    # Must-fail: the plain uniform warp on the same face.
    from scatter_cli.sampling.warps import square_to_triangle

    b = square_to_triangle(u[:, :2])
    uni = np.bincount(locate(np.column_stack([1 - b.sum(1), b]), subs), minlength=len(subs))
    assert chi2_gof(uni, expect)[2] < ALPHA


def texture_mask_quad():
    img = np.zeros((4, 8, 4), np.uint8)
    img[..., 3] = 255
    img[:, 4:, 0] = 255  # red: right half of the texture
    img[:, :, 1] = np.linspace(0, 255, 8).astype(np.uint8)[None, :]  # green: a ramp
    return textured_quad(img)


def exact_u_bins(mesh, channel, edges):
    """Exact mass of each u-bin of the quad (u = x) under weight = bilinear channel."""
    px = np.asarray(mesh.visual.material.image.convert("RGBA"))
    u = (np.arange(200_000) + 0.5) / 200_000
    w = bilinear(px, np.column_stack([u, np.full_like(u, 0.5)]))[:, channel]
    return np.histogram(u, edges, weights=w)[0]


@pytest.mark.slow
@pytest.mark.parametrize("channel", ["r", "g"])
def test_texture_weight_chi_square_and_zero_region(channel):
    mesh = texture_mask_quad()
    n = 40_000
    s = scatter_cli.sample(mesh, n, weight=f"texture:{channel}", attributes=("uv",), precision="float64", seed=9)
    edges = np.linspace(0, 1, 33)
    expect = exact_u_bins(mesh, "rgba".index(channel), edges)
    expect = expect / expect.sum() * n
    counts = np.histogram(s.uv[:, 0], edges)[0]
    assert chi_p(counts, expect) > ALPHA
    if channel == "r":  # texels 0..3 are black: u in [1/16, 7/16] has weight zero
        assert not np.any((s.uv[:, 0] > 1 / 16) & (s.uv[:, 0] < 7 / 16))
    u = scatter_cli.sample(mesh, n, attributes=("uv",), precision="float64", seed=9)  # must-fail: no weight
    assert chi_p(np.histogram(u.uv[:, 0], edges)[0], expect) < ALPHA


@pytest.mark.slow
@pytest.mark.parametrize("weight,mesh", [("vertex-color:g", "boxvertexcolors.glb"), ("texture:a", "cesiummilktruck.glb"),
                                         ("texture:r", "boxtextured.glb")])
def test_weighted_output_identical_for_any_chunk_size(weight, mesh):
    for cs, n in ((1, 700), (333, 5000), (4096, 5000)):  # (a chunk a point: fewer points, as many chunks)
        ref = scatter_cli.sample(SAMPLES / mesh, n, weight=weight, attributes=("color", "object"), seed=10)
        got = scatter_cli.sample(SAMPLES / mesh, n, weight=weight, attributes=("color", "object"), seed=10, chunk_size=cs)
        assert got.points.tobytes() == ref.points.tobytes() and got.color.tobytes() == ref.color.tobytes()


@pytest.mark.slow
def test_bad_weights_are_clear_errors():
    with pytest.raises(ScatterUsageError):
        scatter_cli.sample(SAMPLES / "boxvertexcolors.glb", 10, weight="vertex-color:x")
    with pytest.raises(ScatterError, match="boxtextured.glb.*vertex-color"):
        scatter_cli.sample(SAMPLES / "boxtextured.glb", 10, weight="vertex-color:r")
    with pytest.raises(ScatterError, match="koala.obj.*texture"):
        scatter_cli.sample(SAMPLES / "koala.obj", 10, weight="texture:r")
    black = textured_quad(np.zeros((2, 4, 4), np.uint8))
    with pytest.raises(ScatterError, match="zero"):
        scatter_cli.sample(black, 10, weight="texture:r")


# -- only what is asked for is computed ---------------------------------------------------

def test_xyz_only_decodes_no_texture_and_computes_no_normals(monkeypatch):
    import scatter_cli.surface.texture as texture
    import scatter_cli.surface.data as visuals

    calls = []
    monkeypatch.setattr(texture, "decode", lambda *a, **k: calls.append("decode"))
    monkeypatch.setattr(visuals, "vertex_normal_table", lambda *a, **k: calls.append("normals"))
    monkeypatch.setattr(visuals, "color_source", lambda *a, **k: calls.append("colour"))
    scatter_cli.sample(SAMPLES / "cesiummilktruck.glb", 1000, attributes=("face", "object", "bary"))
    assert calls == []
    scene = trimesh.load(SAMPLES / "cesiummilktruck.glb", process=False)
    scatter_cli.sample(scene, 1000)
    img = scene.geometry["Wheels"].visual.material.baseColorTexture
    assert img._im is None  # Pillow never decoded the pixels
