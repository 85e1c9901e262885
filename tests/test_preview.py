"""`scatter preview`: the geometry of the pictures, the sheets, and the command's errors."""

import functools
import hashlib
import sys

import numpy as np
import pytest

from scatter_cli.commands import preview as PREVIEW  # the module (the package's `preview` is the function)
from scatter_cli.commands import render
from scatter_cli.errors import ScatterError
from scatter_cli.writers.pointfiles import read_points

from .conftest import SAMPLES, run_scatter, run_user, scatter_command, scatter_in_process

Image = pytest.importorskip("PIL.Image")  # the preview extra

WHITE = render.BACKGROUND


def sphere(n, seed=0):
    """(n, 3) points uniform on the unit sphere."""
    v = np.random.default_rng(seed).normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def cube(n, seed=0):
    """(n, 3) points uniform on the surface of the cube [-1, 1]^3, and their (n, 3) normals."""
    rng = np.random.default_rng(seed)
    axis, sign = rng.integers(0, 3, n), rng.choice([-1.0, 1.0], n)
    points = rng.uniform(-1, 1, (n, 3))
    points[np.arange(n), axis] = sign
    normals = np.zeros((n, 3))
    normals[np.arange(n), axis] = sign
    return points, normals


def foreground(image):
    """(h, w) bool: the pixels something was drawn on."""
    return (image != WHITE).any(axis=2)


def write_ply(path, points, normals=None, colors=None):
    """A binary little-endian point PLY as scatter writes it."""
    fields = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    fields += [(c, "<f4") for c in ("nx", "ny", "nz")] if normals is not None else []
    fields += [(c, "u1") for c in ("red", "green", "blue", "alpha")] if colors is not None else []
    rows = np.empty(len(points), dtype=fields)
    for j, c in enumerate("xyz"):
        rows[c] = points[:, j]
    for j, c in enumerate(("nx", "ny", "nz") if normals is not None else ()):
        rows[c] = normals[:, j]
    for j, c in enumerate(("red", "green", "blue", "alpha") if colors is not None else ()):
        rows[c] = colors[:, j]
    kinds = {"<f4": "float", "u1": "uchar"}
    head = ["ply", "format binary_little_endian 1.0", f"element vertex {len(points)}"]
    head += [f"property {kinds[t]} {c}" for c, t in fields] + ["end_header"]
    with open(path, "wb") as f:
        f.write(("\n".join(head) + "\n").encode())
        f.write(rows.tobytes())


# ---- the geometry of the picture ----

def disc_overlap(mask):
    """Intersection over union of ``mask`` with the disc of its area about its centroid."""
    ys, xs = np.nonzero(mask)
    cy, cx = ys.mean() + 0.5, xs.mean() + 0.5
    radius = np.sqrt(mask.sum() / np.pi)
    yy, xx = np.mgrid[: mask.shape[0], : mask.shape[1]] + 0.5
    disc = (yy - cy) ** 2 + (xx - cx) ** 2 <= radius**2
    return (mask & disc).sum() / (mask | disc).sum()


def assert_disc(points):
    colors = np.full((len(points), 3), 128, np.uint8)
    for view in render.VIEWS:
        mask = foreground(render.thumbnail(points, colors, view, "Z", 128))
        assert disc_overlap(mask) > 0.96, view


def test_a_sphere_is_a_disc_from_every_view():
    assert_disc(sphere(20000))


def test_an_ellipsoid_is_not_a_disc():
    with pytest.raises(AssertionError):
        assert_disc(sphere(20000) * [1.0, 1.3, 1.0])  # long in y: every view but front shows it


def red_fraction(points, rgb, view):
    """Fraction of the drawn pixels that are pure red (any brightness), and how many."""
    colors = np.tile(np.array(rgb, np.uint8), (len(points), 1))
    image = render.thumbnail(points, colors, view, "Z", 96).reshape(-1, 3)[foreground(render.thumbnail(
        points, colors, view, "Z", 96)).ravel()]
    red = (image[:, 0] > 100) & (image[:, 1] == 0) & (image[:, 2] == 0)
    return red.mean(), len(image)


def test_a_red_square_is_red():
    rng = np.random.default_rng(1)
    square = np.column_stack([rng.uniform(0, 1, (20000, 2)), np.zeros(20000)])
    fraction, drawn = red_fraction(square, (255, 0, 0), "top")
    assert fraction == 1.0 and drawn > 0.8 * (96 * (1 - 2 * render.MARGIN)) ** 2  # red, and the square filled
    fraction, _ = red_fraction(square, (255, 0, 0), "iso")
    assert fraction == 1.0  # shaded by depth, still red
    fraction, _ = red_fraction(square, (0, 0, 255), "top")
    assert fraction == 0.0  # the broken variant: a blue square is not red


def front_face_share(points, normals):
    """Share of the pixels inside the drawn area (two pixels in from its edge) of a front
    view that have the colour of the -Y face."""
    colors = render.point_colors(points, {"normal": normals})
    face = render.point_colors(np.zeros((1, 3)), {"normal": np.array([[0.0, -1.0, 0.0]])})[0]
    image = render.thumbnail(points, colors, "front", "Z", 128)
    mask = foreground(image)
    inner = mask.copy()
    for shift in (-2, 2):
        inner &= np.roll(mask, shift, axis=0) & np.roll(mask, shift, axis=1)
    return (image[inner] == face).all(axis=1).mean()


@pytest.mark.slow
def test_a_cube_seen_from_the_front_shows_one_face():
    points, normals = cube(150000)  # dense: the discs of the front face close up
    assert front_face_share(points, normals) > 0.99
    turn = np.array([[np.cos(0.6), -np.sin(0.6), 0], [np.sin(0.6), np.cos(0.6), 0], [0, 0, 1]])
    assert front_face_share(points @ turn.T, normals @ turn.T) < 0.8  # turned: two faces show


def assert_back_hidden(draw):
    """A sphere whose back half (y > 0, away from the front camera) comes last in the
    array: seen from the front, its points must not show."""
    points = sphere(30000, seed=2)
    points = points[np.argsort(points[:, 1] > 0, kind="stable")]
    back = points[:, 1] > 0
    colors = np.where(back[:, None], np.array([0, 0, 255], np.uint8), np.array([255, 0, 0], np.uint8))
    image = draw(points, colors, "front", "Z", 128)
    drawn = image[foreground(image)]
    blue = (drawn[:, 2] > 0) & (drawn[:, 0] == 0)
    assert blue.mean() < 0.01


def test_the_depth_buffer_hides_the_back_half():
    assert_back_hidden(render.thumbnail)


def test_without_the_depth_test_the_back_half_shows():
    with pytest.raises(AssertionError):
        assert_back_hidden(functools.partial(render.thumbnail, depth_test=False))


def test_a_volume_is_cut_open_to_show_its_inside():
    rng = np.random.default_rng(4)
    volume = rng.uniform(-1, 1, (40000, 3))
    inside = (np.linalg.norm(volume, axis=1) < 0.6).astype(float)
    colors = render.point_colors(volume, {"inside": inside})
    for cut, seen in ((True, render.INSIDE_RGB), (False, render.OUTSIDE_RGB)):  # uncut: the outer points hide it
        centre = render.thumbnail(volume, colors, "front", "Z", 96, cut=cut)[40:56, 40:56].reshape(-1, 3)
        hue = np.array(seen) / np.linalg.norm(seen)
        cosine = centre @ hue / np.maximum(np.linalg.norm(centre, axis=1), 1)
        assert np.mean(cosine > 0.99) > 0.9, cut



@pytest.mark.slow
def test_preview_cuts_open_files_with_inside_or_sdf(tmp_path):
    rng = np.random.default_rng(5)
    volume = rng.uniform(-1, 1, (20000, 3))
    sdf = np.linalg.norm(volume, axis=1) - 0.6
    np.savetxt(tmp_path / "v.csv", np.column_stack([volume, sdf]), delimiter=",", header="x,y,z,sdf", comments="")
    tile, _, _ = PREVIEW.draw_input(str(tmp_path / "v.csv"), ("front",), 96, {})
    centre = tile[40:56, 40:56].reshape(-1, 3).astype(int)
    assert np.mean(centre[:, 0] > centre[:, 2]) > 0.9  # vermillion (inside), not blue


def test_pinholes_close_and_silhouettes_stay():
    near, far = np.uint64(10 << 32), np.uint64((render.DEPTH_STEPS - 5) << 32)
    keys = np.full((9, 9), render.EMPTY, dtype=np.uint64)
    keys[1:5, 1:8] = near + np.arange(28, dtype=np.uint64).reshape(4, 7)  # a near surface, top half
    keys[3, 4] = far + np.uint64(99)  # a pinhole through which a far point shows
    keys[2, 2] = render.EMPTY  # a pinhole onto the background
    before = keys.copy()
    render.fill_holes(keys)
    assert keys[3, 4] == before[2, 3] and keys[2, 2] == before[1, 1]  # the nearest neighbour's point
    changed = keys != before
    changed[3, 4] = changed[2, 2] = False
    assert not changed.any()  # the surface's edges and the background stay


def test_views_follow_the_up_axis():
    for up in ("Z", "Y"):
        rows = {v: render.camera(v, up) for v in render.VIEWS}
        for m in rows.values():
            assert np.allclose(m @ m.T, np.eye(3)) and np.isclose(np.linalg.det(m), 1.0)
        up_vector = [0, 0, 1] if up == "Z" else [0, 1, 0]
        assert np.allclose(rows["top"][2], up_vector)  # top looks down the up axis
        for v in ("front", "side", "iso"):
            assert np.dot(rows[v][1], up_vector) > 0.8  # the up axis is up on screen
    assert np.allclose(render.camera("front", "Z")[2], [0, -1, 0])  # looks along +Y
    assert np.allclose(render.camera("front", "Y")[2], [0, 0, 1])  # looks along -Z
    assert np.allclose(render.camera("side", "Z")[2], [1, 0, 0])  # looks along -X
    # a tower along the up axis stands tall in every view but top; along another axis it does not
    for up, axis in (("Z", 2), ("Y", 1)):
        low, high = np.full(3, -0.2), np.full(3, 0.2)
        low[axis], high[axis] = 0, 2
        tower = np.random.default_rng(3).uniform(low, high, (5000, 3))
        colors = np.full((5000, 3), 90, np.uint8)
        for view in render.VIEWS:
            ys, xs = np.nonzero(foreground(render.thumbnail(tower, colors, view, up, 64)))
            assert (np.ptp(ys) > 2 * np.ptp(xs)) == (view != "top"), (up, view)
        ys, xs = np.nonzero(foreground(render.thumbnail(tower, colors, "front", "Y" if up == "Z" else "Z", 64)))
        assert not np.ptp(ys) > 2 * np.ptp(xs), up  # the wrong up axis: not standing


def test_colours_come_from_colour_then_inside_then_normals_then_height():
    pts = sphere(100)
    normal = pts
    colour = np.tile(np.array([[10, 200, 30, 255]], np.uint8), (100, 1))
    inside = (pts[:, 0] > 0).astype(np.float64)
    picked = render.point_colors(pts, {"normal": normal, "color": colour, "inside": inside})
    assert (picked == [10, 200, 30]).all()
    two = render.point_colors(pts, {"normal": normal, "inside": inside})
    assert len(np.unique(two, axis=0)) == 2
    assert (render.point_colors(pts, {"sdf": 0.5 - inside}) == two).all()  # sdf < 0: inside
    assert (render.point_colors(pts, {"normal": normal}) == np.rint((normal + 1) * 127.5)).all()
    height = render.point_colors(pts, {}).astype(int)
    low, high = np.argmin(pts[:, 2]), np.argmax(pts[:, 2])
    assert (height[low] == render.HEIGHT_RAMP[0]).all() and (height[high] == render.HEIGHT_RAMP[-1]).all()


def blue_yellow(rgb):
    r, g, b = np.asarray(rgb, dtype=float)
    return b - (r + g) / 2


def test_inside_and_outside_hues_differ_for_red_green_colour_blindness():
    # Protanopes and deuteranopes keep the blue-yellow axis: the two hues must sit on
    # opposite sides of it (a red/green pair does not).
    assert blue_yellow(render.INSIDE_RGB) * blue_yellow(render.OUTSIDE_RGB) < 0
    assert blue_yellow((213, 30, 0)) * blue_yellow((0, 170, 60)) > 0  # the variant that must fail


# ---- reading point files ----

FORMATS = ["ply", "csv", "xyz", "npy", "pcd", "las", "laz", "usda", "usdc"]


@pytest.fixture(scope="module")
def point_files(tmp_path_factory):
    """Every format the command writes, as ``scatter sample`` writes it: the first file
    through a real process, the rest through the command's entry point in this process."""
    folder = tmp_path_factory.mktemp("points")
    spot, box = SAMPLES / "spot_triangulated.obj", SAMPLES / "boxvertexcolors.glb"
    jobs = [(spot, f"spot.{fmt}", ["-a", "normal"]) for fmt in FORMATS]
    jobs += [(spot, f"spot-ascii.{fmt}", ["-a", "normal", "--ascii"]) for fmt in ("ply", "pcd")]
    jobs += [(box, f"box.{fmt}", ["-a", "color"]) for fmt in ("pcd", "las", "usda")]
    for k, (mesh, name, options) in enumerate(jobs):
        (run_scatter if k == 0 else scatter_in_process)("sample", mesh, "-n", "3000", *options, "-o", folder / name,
                                                        check=True)
    return folder


@pytest.mark.slow
def test_every_format_scatter_writes_reads_back(point_files):
    rows = np.load(point_files / "spot.npy")  # NumPy's own reader: the reference
    points, normals = (np.stack([rows[c] for c in names], axis=1) for names in ("xyz", ("nx", "ny", "nz")))
    for path in sorted(point_files.iterdir()):
        if path.stem == "box":
            continue
        got = read_points(path)
        assert got.total == 3000 and np.allclose(got.points, points, atol=1e-5), path.name
        assert set(got.attributes) == {"normal"} and np.allclose(got.attributes["normal"], normals, atol=1e-5), path.name
        assert got.up_axis == ("Y" if path.suffix.startswith(".usd") else "Z")  # the USD writer's default


@pytest.mark.slow
def test_colour_reads_back(point_files):
    from scatter_cli import sample

    expected = sample(SAMPLES / "boxvertexcolors.glb", 3000, attributes="color").color[:, :3]
    assert len(np.unique(expected, axis=0)) > 10
    for fmt in ("pcd", "las", "usda"):  # packed rgb, 16-bit channels, displayColor floats
        assert (read_points(point_files / f"box.{fmt}").attributes["color"] == expected).all(), fmt


@pytest.mark.slow
def test_large_files_are_decimated_evenly(point_files):
    full = read_points(point_files / "spot.ply").points
    for name in ("spot.ply", "spot.npy", "spot.pcd"):  # binary: every k-th row
        assert (read_points(point_files / name, 1000).points == full[::3]).all(), name
    for name in ("spot.csv", "spot.xyz", "spot.las", "spot-ascii.ply"):  # text and LAS: runs spread evenly
        got = read_points(point_files / name, 640).points
        rows = np.flatnonzero(np.isclose(full[:, None, 0], got[None, :, 0], atol=1e-5).any(axis=1))
        assert 600 <= len(got) <= 700 and rows.min() < 100 and rows.max() > 2900, name
        assert np.histogram(rows, bins=8, range=(0, 3000))[0].min() > 40, name  # every eighth of the file


# ---- the sheet ----

def small_files(folder, k):
    folder.mkdir(exist_ok=True)
    for i in range(k):
        write_ply(folder / f"p{i:02d}.ply", sphere(500, seed=i) * (1 + i))
    return folder


def cells(sheet_path, size, views=1):
    """[(row, column) of the cells with ink], the sheet's (height, width)."""
    image = np.asarray(Image.open(sheet_path).convert("RGB"))
    gap, cell_h = PREVIEW.GAP, size + PREVIEW.CAPTION
    cell_w = size * views
    rows = (image.shape[0] - gap) // (cell_h + gap)
    cols = (image.shape[1] - gap) // (cell_w + gap)
    inked = []
    for r in range(rows):
        for c in range(cols):
            y, x = gap + r * (cell_h + gap), gap + c * (cell_w + gap)
            if foreground(image[y : y + size, x : x + cell_w]).any():
                inked.append((r, c))
    return inked, image.shape[:2]


@pytest.mark.slow
def test_pages_and_grid(tmp_path):
    src = small_files(tmp_path / "in", 7)
    proc = run_scatter("preview", src, "--per-page", "3", "--columns", "2", "--size", "64",
                       "-o", tmp_path / "sheet-{page}.png")
    assert proc.returncode == 0, proc.stderr
    assert sorted(p.name for p in tmp_path.glob("*.png")) == ["sheet-1.png", "sheet-2.png", "sheet-3.png"]
    gap, cell_h = PREVIEW.GAP, 64 + PREVIEW.CAPTION
    full, shape = cells(tmp_path / "sheet-1.png", 64)
    assert full == [(0, 0), (0, 1), (1, 0)] and shape == (gap + 2 * (cell_h + gap), gap + 2 * (64 + gap))
    last, shape = cells(tmp_path / "sheet-3.png", 64)
    assert last == [(0, 0)] and shape == (gap + cell_h + gap, gap + 64 + gap)


@pytest.mark.slow
def test_views_side_by_side_and_default_columns(tmp_path):
    src = small_files(tmp_path / "in", 5)
    proc = run_scatter("preview", src, "--view", "front", "--view", "top", "--size", "48", "-o", tmp_path / "s.png")
    assert proc.returncode == 0, proc.stderr
    inked, _ = cells(tmp_path / "s.png", 48, views=2)
    assert inked == [(0, 0), (0, 1), (1, 0), (1, 1), (2, 0)]  # ceil(sqrt(5 / 2)) = 2 columns
    image = np.asarray(Image.open(tmp_path / "s.png").convert("RGB"))
    g = PREVIEW.GAP
    assert foreground(image[g : g + 48, g : g + 48]).any() and foreground(image[g : g + 48, g + 48 : g + 96]).any()


def test_folders_are_searched_recursively_in_sorted_order(tmp_path):
    src = tmp_path / "in"
    (src / "b").mkdir(parents=True)
    (src / "a").mkdir()
    write_ply(src / "b" / "x.ply", sphere(300))
    write_ply(src / "a" / "z.ply", sphere(300) * [1, 1, 0.1])
    (src / "notes.txt").write_text("not points")
    found = PREVIEW.collect([src])
    assert found.paths == [str(src / "a" / "z.ply"), str(src / "b" / "x.ply")]
    lst = tmp_path / "list.txt"
    lst.write_text(f"{src / 'b' / 'x.ply'}\n")
    assert PREVIEW.collect([], from_list=lst).paths == [str(src / "b" / "x.ply")]


def caption_ink(image, slot_origin, size, line):
    x, y = slot_origin
    strip = image[y + size + line * PREVIEW.LINE : y + size + (line + 1) * PREVIEW.LINE + 2, x : x + size]
    return (strip.min(axis=2) < 128).sum()


@pytest.mark.slow
def test_captions_name_and_count(tmp_path):
    src = small_files(tmp_path / "in", 2)
    run_scatter("preview", src, "--size", "96", "-o", tmp_path / "s.png", check=True)
    image = np.asarray(Image.open(tmp_path / "s.png").convert("RGB"))
    g = PREVIEW.GAP
    for slot in ((g, g), (2 * g + 96, g)):
        assert caption_ink(image, slot, 96, 0) > 30 and caption_ink(image, slot, 96, 1) > 30
    tile, lines, _ = PREVIEW.draw_input(str(src / "p00.ply"), ("iso",), 32, {})
    assert lines == ["500 points"] and tile.shape == (32, 32, 3)
    assert PREVIEW.shorten("collection/chairs/0042/model.ply", 16) == "...042/model.ply"


def test_meshes_are_sampled_and_the_count_shown(tmp_path):
    _, lines, _ = PREVIEW.draw_input(str(SAMPLES / "icosahedron_binary.stl"), ("iso",), 32,
                                  PREVIEW.mesh_options({"count": 1234}))
    assert lines == ["1,234 points sampled"]
    pts, _, up, _ = PREVIEW.load(str(SAMPLES / "boxtextured.glb"), PREVIEW.mesh_options({"count": 100}))
    assert up == "Y" and len(pts) == 100  # glTF is Y up


@pytest.mark.slow
def test_same_inputs_same_bytes(tmp_path):
    src = small_files(tmp_path / "in", 3)
    args = ["preview", src, SAMPLES / "hemisphere.off", "-n", "2000", "--size", "64"]
    digests = set()
    for name in ("a.png", "b.png"):
        run_scatter(*args, "-o", tmp_path / name, check=True)
        digests.add(hashlib.sha256((tmp_path / name).read_bytes()).hexdigest())
    assert len(digests) == 1
    run_scatter(*args, "--seed", "1", "-o", tmp_path / "c.png", check=True)  # another sample: other bytes
    assert hashlib.sha256((tmp_path / "c.png").read_bytes()).hexdigest() not in digests


@pytest.mark.slow
def test_bad_inputs_are_crossed_out_and_the_sheet_written(tmp_path):
    src = small_files(tmp_path / "in", 1)
    (tmp_path / "broken.ply").write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 100\n"
                                          b"property float x\nproperty float y\nproperty float z\nend_header\n" + bytes(12))
    proc = run_user(scatter_command("preview", "in/p00.ply", "broken.ply", "missing.csv", "--size", "64",
                                    "-o", "s.png"), cwd=tmp_path)
    assert proc.returncode == 1
    err = proc.stderr.decode().strip().splitlines()
    assert err[0].startswith("error: broken.ply: ") and "truncated" in err[0]
    assert err[1] == "error: missing.csv: no such file"
    assert err[2] == "preview: 2 of 3 inputs failed (crossed out on s.png)" and len(err) == 3
    image = np.asarray(Image.open(tmp_path / "s.png").convert("RGB"))
    g = PREVIEW.GAP
    for col in (1, 2):  # columns = ceil(sqrt(3)) = 2: cells 1 and 2 are (0, 1) and (1, 0)
        x, y = g + (col % 2) * (64 + g), g + (col // 2) * (64 + PREVIEW.CAPTION + g)
        cell = image[y : y + 64, x : x + 64]
        diagonal = cell[np.arange(36, 60), np.arange(36, 60)]  # (its error in the top half)
        assert (diagonal == PREVIEW.CROSS_RGB).all(axis=1).mean() > 0.9  # crossed out
        assert (cell == PREVIEW.FAILED_RGB).all(axis=2).mean() > 0.5
    good = image[g : g + 64, g : g + 64]
    assert foreground(good).any() and not (good == PREVIEW.CROSS_RGB).all(axis=2).any()


@pytest.mark.slow
@pytest.mark.parametrize("args, message", [
    (["--size", "0"], "error: --size must be a positive integer, not 0"),
    (["--view", "up"], "error: unknown view 'up' (choose from: iso, front, side, top)"),
    (["--per-page", "1"], "error: 2 inputs make 2 sheets of 1: put {page} in the output name (s.png)"),
    (["-o", "s.jpg"], "error: preview writes PNG: the output must end in .png, not 's.jpg'"),
])
def test_usage_errors(tmp_path, args, message):
    small_files(tmp_path / "in", 2)
    out = [] if "-o" in args else ["-o", "s.png"]
    proc = run_user(scatter_command("preview", "in", *args, *out), cwd=tmp_path)
    assert proc.returncode == 2
    assert proc.stderr.decode().splitlines() == [message]
    assert not list(tmp_path.glob("s.*"))


@pytest.mark.slow
def test_non_finite_points_are_counted_and_a_missing_folder_is_an_error_before_work(tmp_path):
    points = sphere(400)
    points[:3] = np.nan
    write_ply(tmp_path / "nan.ply", points)
    _, lines, _ = PREVIEW.draw_input(str(tmp_path / "nan.ply"), ("iso",), 32, {})
    assert lines == ["400 points, 3 not finite (not drawn)"]
    proc = run_scatter("preview", tmp_path / "nan.ply", "-o", tmp_path / "no" / "s.png")
    assert proc.returncode == 1
    assert proc.stderr.decode().splitlines() == [f"error: {tmp_path / 'no' / 's.png'}: cannot write: folder "
                                                 f"'{tmp_path / 'no'}' does not exist"]


def test_missing_pillow_is_named(tmp_path, monkeypatch):
    src = small_files(tmp_path / "in", 1)
    monkeypatch.setitem(sys.modules, "PIL", None)
    with pytest.raises(ScatterError, match=r"needs Pillow.*pip install pillow"):
        PREVIEW.preview([src], tmp_path / "s.png")
    assert not (tmp_path / "s.png").exists()


def test_python_api_returns_the_sheets(tmp_path):
    import scatter_cli

    src = small_files(tmp_path / "in", 5)
    sheets = scatter_cli.preview([src], tmp_path / "p{page:02d}.png", size=32, per_page=2)
    assert sheets == [str(tmp_path / f"p{i:02d}.png") for i in (1, 2, 3)] and sheets.failed == []
    with pytest.raises(TypeError, match="colour"):
        scatter_cli.preview([src], tmp_path / "q{page}.png", colour="red")
    assert not list(tmp_path.glob("q*.png"))


@pytest.mark.slow
def test_help_imports_neither_numpy_nor_pillow():
    code = ("import sys; from scatter_cli.cli import main; code = main(['preview', '--help']); "
            "print(code, sorted(m for m in ('numpy', 'PIL') if m in sys.modules))")
    proc = run_user([sys.executable, "-c", code])
    out = proc.stdout.decode().strip().splitlines()
    assert "Usage:" in out[0] and out[-1] == "0 []"


# ---- pinholes, legends, errors and terrains ----

ONE_HOT = np.array([[255, 0, 0], [0, 255, 0], [0, 0, 255], [255, 255, 0], [255, 0, 255], [0, 255, 255]], np.uint8)


def cube_faces(n, seed=0):
    """(n, 3) points uniform on the cube [-1, 1]^3, and (n,) the face of each (0..5:
    axis + 3 for the + side)."""
    points, normals = cube(n, seed)
    axis = np.argmax(np.abs(normals), axis=1)
    return points, axis + 3 * (normals[np.arange(n), axis] > 0)


def face_interiors(view, size, inset):
    """(6, size, size) bool: the pixels of a thumbnail of the cube [-1, 1]^3 inside the
    picture of each face that ``view`` sees (its normal toward the viewer), at least
    ``inset`` pixels from the face's edges; nothing for the faces it does not see."""
    corners = render.box_corners(np.array([[-1.0] * 3, [1.0] * 3]))
    x, y, _, _ = render.project(corners, view, "Z", size)
    toward = render.camera(view)[2]
    yy, xx = np.mgrid[:size, :size] + 0.5
    masks = np.zeros((6, size, size), bool)
    for face in range(6):
        axis, side = face % 3, 1.0 if face >= 3 else -1.0
        if side * toward[axis] < 1e-9:
            continue
        quad = np.flatnonzero(corners[:, axis] == side)
        centre = np.array([x[quad].mean(), y[quad].mean()])
        order = quad[np.argsort(np.arctan2(y[quad] - centre[1], x[quad] - centre[0]))]
        inside = np.ones((size, size), bool)
        for a, b in zip(order, np.roll(order, -1)):  # inset from each edge of the convex quad
            edge = np.array([x[b] - x[a], y[b] - y[a]])
            normal = np.array([-edge[1], edge[0]]) / np.hypot(*edge)
            if normal @ (centre - [x[a], y[a]]) < 0:
                normal = -normal
            inside &= (xx - x[a]) * normal[0] + (yy - y[a]) * normal[1] >= inset
        masks[face] = inside
    return masks


def assert_faces_closed(size=128, n=20_000, seed=0):
    """Seen from every view, a cube of n points shows in the inner part of each visible
    face the colour of that face only: no pinhole onto the background or the back."""
    points, face = cube_faces(n, seed)
    for view in render.VIEWS:
        image = render.thumbnail(points, ONE_HOT[face], view, "Z", size)
        lit = image > 0  # depth shading keeps the channels a face's colour lights
        for k, mask in enumerate(face_interiors(view, size, render.MAX_SPLAT + 1)):
            if mask.any():
                assert (lit[mask] == (ONE_HOT[k] > 0)).all(axis=1).all(), (view, k)


@pytest.mark.parametrize("size,n,seed", [(256, 20_000, 0), (128, 5_000, 1), (200, 30_000, 2), (128, 20_000, 3)])
def test_no_pinholes_on_the_faces_of_a_cube_in_any_view(size, n, seed, monkeypatch):
    """Sets dense enough for discs of MAX_SPLAT pixels: preview's default (20,000 points
    at 256 pixels), the same density smaller, denser ones; the broken variant, one disc size
    from the count, leaves holes in each."""
    assert_faces_closed(size, n, seed)

    def one_radius(x, y, depth, depth_pixels, size):  # the broken variant: one disc size from the count
        return np.full(len(x), np.clip(1.2 * size / np.sqrt(len(x)), 1.0, render.MAX_SPLAT))

    monkeypatch.setattr(render, "splat_radii", one_radius)
    with pytest.raises(AssertionError):
        assert_faces_closed(size, n, seed)


def assert_wrapped_clear_of_the_cross(sheet, message):
    """The error's lines break between words and, drawn, no stroke of the cross is in
    the box behind them."""
    lines = [t for _, _, t, rgb in sheet.texts if rgb == PREVIEW.CROSS_RGB]
    assert " ".join(lines) == message
    words = message.split()
    assert sum(len(line.split()) for line in lines) == len(words)  # no word cut in two
    path = sheet.written
    image = np.asarray(Image.open(path).convert("RGB"))
    x0, y0, x1, y1 = sheet.boxes[0]
    box = image[y0 : y1 + 1, x0 : x1 + 1]
    text = np.zeros(box.shape[:2], bool)
    for x, y, t, _ in sheet.texts:  # the glyphs' cells: 6 x 12 pixels a character
        if y0 <= y <= y1:
            text[y - y0 : y - y0 + PREVIEW.LINE, x - x0 : x - x0 + PREVIEW.CHAR * len(t)] = True
    red = (box == PREVIEW.CROSS_RGB).all(axis=2)
    assert not (red & ~text).any()


def failed_sheet(tmp_path, message):
    sheet = PREVIEW.Sheet(1, 1, 256, 1)
    sheet.failed(0, "bad.obj", message)
    sheet.written = tmp_path / "s.png"
    sheet.write(sheet.written)
    return sheet


def test_an_error_wraps_between_words_clear_of_the_cross(tmp_path, monkeypatch):
    message = ("bad.obj: truncated: the file ends at byte 100,000, at vertex 8,301 of 49,999 (of the 49,999 "
               "vertex and 100,002 face rows its header declares)")
    assert_wrapped_clear_of_the_cross(failed_sheet(tmp_path, message), message)
    chop = lambda text, chars, rows: [text[i : i + chars] for i in range(0, len(text), chars)][:rows]
    monkeypatch.setattr(PREVIEW, "wrap_lines", chop)  # the broken variant: lines cut at a fixed width
    with pytest.raises(AssertionError):
        assert_wrapped_clear_of_the_cross(failed_sheet(tmp_path, message), message)
    monkeypatch.undo()
    sheet = failed_sheet(tmp_path, message)
    box = sheet.boxes.pop()  # the other broken variant: the cross drawn over the text
    sheet.write(sheet.written)
    sheet.boxes.append(box)
    with pytest.raises(AssertionError):
        assert_wrapped_clear_of_the_cross(sheet, message)


def legend_of(path, tmp_path):
    """The legend's labels and the colours of its swatches, as drawn on a sheet of ``path``."""
    tile, lines, legend = PREVIEW.draw_input(str(path), ("iso",), 128, {})
    sheet = PREVIEW.Sheet(1, 1, 128, 1)
    sheet.put(0, tile, [str(path), *lines], legend)
    x, y = sheet.origin(0)
    labels = [t for tx, ty, t, _ in sheet.texts if ty < y + 128]
    swatches = [tuple(sheet.canvas[y + 4 + i * PREVIEW.LINE + 4, x + 8]) for i in range(len(labels))]
    return dict(zip(labels, swatches))


def test_inside_and_outside_colours_have_a_legend(tmp_path, monkeypatch):
    rng = np.random.default_rng(6)
    volume = rng.uniform(-1, 1, (5000, 3))
    sdf = np.linalg.norm(volume, axis=1) - 0.6
    np.savetxt(tmp_path / "v.csv", np.column_stack([volume, sdf]), delimiter=",", header="x,y,z,sdf", comments="")
    write_ply(tmp_path / "s.ply", sphere(5000), normals=sphere(5000))
    assert legend_of(tmp_path / "v.csv", tmp_path) == {"inside": render.INSIDE_RGB, "outside": render.OUTSIDE_RGB}
    assert legend_of(tmp_path / "s.ply", tmp_path) == {}  # normals need no legend
    monkeypatch.setattr(render, "legend", lambda attributes: [])  # the broken variant
    assert legend_of(tmp_path / "v.csv", tmp_path) == {}


def relief_order(points, normals):
    """Spearman's correlation of the height of each point with the place of its hue on
    the height ramp (its nearest ramp colour, brightness aside)."""
    colors = render.point_colors(points, {"normal": normals}).astype(float)
    ramp = render.HEIGHT_RAMP / np.linalg.norm(render.HEIGHT_RAMP, axis=1, keepdims=True)
    hue = colors / np.maximum(np.linalg.norm(colors, axis=1, keepdims=True), 1)
    place = np.argmax(hue @ ramp.T, axis=1)
    rank = lambda v: np.argsort(np.argsort(v, kind="stable"), kind="stable")
    return np.corrcoef(rank(points[:, 2]), rank(place))[0, 1]


def test_a_terrain_is_drawn_as_a_relief_map(monkeypatch):
    from .conftest import terrain

    import scatter_cli

    land = scatter_cli.sample(terrain(), 20_000, attributes=("normal",), precision="float64")
    assert relief_order(land.points, land.normal) > 0.9  # height reads as the ramp: hills yellow, valleys violet
    ball = sphere(5000)
    assert (render.point_colors(ball, {"normal": ball}) == np.rint((ball + 1) * 127.5)).all()  # not a height field
    # lit from the north-west: a slope facing it is brighter than one facing away
    pair = np.array([[0, 0, 0], [0, 0, 0.0]])
    slopes = np.array([[-0.5, 0.5, 0.707], [0.5, -0.5, 0.707]])
    lit = render.point_colors(pair, {"normal": slopes}).astype(int).sum(axis=1)
    assert lit[0] > lit[1]
    monkeypatch.setattr(render, "HEIGHT_FIELD", 1.01)  # the broken variant: a terrain in normal colours
    assert relief_order(land.points, land.normal) < 0.5
