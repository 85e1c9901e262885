"""``scatter preview``: contact sheets of point sets, one captioned thumbnail per input.

Inputs are listed first (folders searched recursively, sorted, as ``batch`` lists
them), then read one at a time: a point file through its format's reader, the one
``merge`` reads it with (:mod:`scatter_cli.writers.pointfiles`; evenly decimated to at
most ``MAX_DRAWN`` points), a mesh sampled through
:func:`scatter_cli.api.prepare`. Each is drawn by :mod:`scatter_cli.commands.render` into the
page, and a page is encoded (Pillow: PNG and captions) and written as soon as it is
full, so memory does not grow with the number of inputs.
"""

from __future__ import annotations

import dataclasses
import io
import math
import numbers
import os
import textwrap
from concurrent.futures import ThreadPoolExecutor

from ..engines.batch import Inputs
from ..errors import ScatterError, ScatterUsageError
from ..loading.formats import MESH_SUFFIXES
from ..writers.formats import SEARCHED_SUFFIXES

# This module imports only the standard library at the top (NumPy and Pillow inside the
# functions): ``scatter_cli.preview`` is the function, imported with the package.

MAX_DRAWN = 200_000  # points drawn per input at most: a 256 px thumbnail shows no more
DEFAULT_COUNT = 20_000  # points sampled on a mesh
# What a folder is searched for: meshes and point files (a point file of a suffix the
# search leaves out, such as .txt, is read when given by name).
FOLDER_SUFFIXES = tuple(sorted(set(MESH_SUFFIXES) | {"." + s for s in SEARCHED_SUFFIXES}))
VIEWS = ("iso", "front", "side", "top")  # as render.VIEWS
GAP = 8  # pixels between cells and around the sheet
LINE = 12  # caption line height (Pillow's default bitmap font is 11 px high)
CAPTION = 2 * LINE + 4  # under each thumbnail: the name, then the point count
CHAR = 6  # width of a character of the default bitmap font
SWATCH = 8  # side of a legend's colour square
PNG_OPTIONS = {"format": "PNG", "compress_level": 3, "optimize": False}  # fixed: same bytes every run
TEXT_RGB, NOTE_RGB, FAILED_RGB, CROSS_RGB = (20, 20, 20), (90, 90, 90), (236, 236, 236), (200, 30, 30)


class Sheets(list):
    """The sheets written (paths, in page order); ``failed``: [(input, error)] of the
    inputs drawn as crossed-out cells; ``inputs``: how many inputs there were."""

    failed: list
    inputs: int


def preview(inputs, output, *, size=256, columns=None, views=("iso",), per_page=100, from_list=None, warn=None,
            **sample_options) -> list[str]:
    """Write contact sheets of ``inputs`` (point files, meshes, folders) to ``output``, a
    ``.png`` path with ``{page}`` in it when there is more than one page.

    ``size``: thumbnail side in pixels; ``columns``: cells per row (default: a square
    page); ``views``: one or more of iso, front, side, top, drawn side by side;
    ``per_page``: inputs per sheet; ``from_list``: a file of paths, one a line ('-':
    standard input). ``sample_options`` (those of :func:`scatter_cli.sample`) are for meshes
    (``count`` default 20000, ``attributes`` default normal). ``warn(message)`` is
    called with each failed input's error. Returns :class:`Sheets`, a list of the
    sheets written with ``.failed``, the inputs that could not be drawn.
    """
    views = check_options(output, size, columns, views, per_page)
    sample_options = mesh_options(sample_options)
    image_module()
    found = collect(inputs, from_list)
    pages = math.ceil(len(found) / per_page)
    if pages > 1 and not _has_page_field(output):
        raise ScatterUsageError(f"{len(found)} inputs make {pages} sheets of {per_page}: put {{page}} in the output "
                                f"name ({output})")
    folder = os.path.dirname(os.path.abspath(page_name(output, 1)))
    if not os.path.isdir(folder):
        raise ScatterError(f"{output}: cannot write: folder '{os.path.dirname(os.fspath(output)) or '.'}' does not exist")
    columns = columns or default_columns(min(per_page, len(found)), len(views))
    sheets = Sheets()
    sheets.failed, sheets.inputs = [], len(found)
    # A page is encoded and written in a second thread while the next one is drawn (the
    # PNG encoder releases the GIL): at most two pages in memory.
    with ThreadPoolExecutor(max_workers=1) as writer:
        pending = None
        for page in range(pages):
            first = page * per_page
            sheet = draw_page(found.paths[first : first + per_page], columns, size, views, sample_options,
                              sheets.failed, warn)
            if pending is not None:
                pending.result()
            name = page_name(output, page + 1)
            pending = writer.submit(sheet.write, name)
            sheets.append(name)
        pending.result()
    return sheets


def draw_page(paths, columns, size, views, sample_options, failed, warn):
    """The Sheet of ``paths``; inputs that fail are crossed out and added to ``failed``."""
    sheet = Sheet(len(paths), columns, size, len(views))
    for slot, path in enumerate(paths):
        try:
            tile, lines, legend = draw_input(path, views, size, sample_options)
        except ScatterError as exc:
            sheet.failed(slot, path, str(exc))
            failed.append((path, str(exc)))
            if warn:
                warn(str(exc))
        else:
            sheet.put(slot, tile, [path, *lines], legend)
    return sheet


def check_options(output, size, columns, views, per_page):
    """The views as a tuple; ScatterUsageError for any bad option."""
    for name, value in (("--size", size), ("--per-page", per_page), ("--columns", columns)):
        if value is not None and (not isinstance(value, numbers.Integral) or value < 1):
            raise ScatterUsageError(f"{name} must be a positive integer, not {value!r}")
    views = (views,) if isinstance(views, str) else tuple(views or ("iso",))
    unknown = [v for v in views if v not in VIEWS]
    if unknown:
        raise ScatterUsageError(f"unknown view '{unknown[0]}' (choose from: {', '.join(VIEWS)})")
    text = os.fspath(output)
    if not text.lower().endswith(".png"):
        raise ScatterUsageError(f"preview writes PNG: the output must end in .png, not '{text}'")
    try:
        page_name(text, 1)
    except (KeyError, IndexError, ValueError) as exc:
        raise ScatterUsageError(f"bad output name '{text}': the only field is {{page}} ({exc})") from None
    return views


def mesh_options(options: dict):
    """The :class:`~scatter_cli.run.options.SampleOptions` of meshes sampled on the fly
    (``count`` 20,000 and ``attributes`` normal, or inside for volume runs, and sharp
    with ``--edges``, unless given), checked before any work: usage errors once, not
    once per mesh."""
    from ..run.options import SampleOptions

    options = dict(options)
    if options.get("count") is None and options.get("density") is None:
        options["count"] = DEFAULT_COUNT
    o = SampleOptions(**options)  # an unknown option is a TypeError, as for a function
    if not o.attributes:
        wanted = ("inside",) if o.volume_run else ("normal",)
        o = dataclasses.replace(o, attributes=wanted + (("sharp",) if o.edges not in (None, 0, "0") else ()))
    return o.check()


def page_name(output, page):
    return os.fspath(output).format(page=page)


def _has_page_field(output):
    return page_name(output, 1) != page_name(output, 2)


def default_columns(cells, views):
    """Columns that make a page of ``cells`` about square (cells ``views`` thumbnails wide)."""
    return max(1, math.ceil(math.sqrt(cells / views)))


def collect(inputs, from_list=None) -> Inputs:
    found = Inputs(FOLDER_SUFFIXES)
    for item in [inputs] if isinstance(inputs, (str, os.PathLike)) else inputs or ():
        found.add(item)
    if from_list is not None:
        found.add_list(os.fspath(from_list))
    if not len(found):
        raise ScatterUsageError("no inputs to preview (no point files or meshes given or found)")
    return found


def image_module():
    """Pillow's Image, ImageDraw and ImageFont; a one-line error naming it when missing."""
    try:
        from PIL import Image, ImageDraw, ImageFont
    except ImportError:
        raise ScatterError("scatter preview needs Pillow to write PNG: pip install pillow") from None
    return Image, ImageDraw, ImageFont


# ---- one input ----

def load(path, sample_options):
    """(points (m, 3) float64, attributes, up axis, caption) of a point file or a mesh
    (sampled with ``sample_options``, a :class:`~scatter_cli.run.options.SampleOptions`)."""
    from ..writers.pointfiles import IsMesh, point_format, read_points

    if os.path.isdir(path):
        raise ScatterError(f"{path}: is a directory")
    if not os.path.exists(path):
        raise ScatterError(f"{path}: no such file")
    if point_format(path) is None:
        return sample_mesh(path, sample_options)
    try:
        pts = read_points(path, MAX_DRAWN)
    except IsMesh:  # a PLY with faces, a USD stage without points
        return sample_mesh(path, sample_options)
    note = f"{pts.total:,} points" + (f", {len(pts.points):,} drawn" if len(pts.points) < pts.total else "")
    return pts.points, pts.attributes, pts.up_axis, note


def sample_mesh(path, options):
    import numpy as np

    from .. import api
    from ..writers.pointfiles import stride

    run = api.prepare(path, options=options)
    samples = run.collect()
    n = len(samples)
    every = stride(n, MAX_DRAWN)
    attributes = {k: v[::every] for k, v in samples.attributes.items()}
    note = f"{n:,} points sampled" + (f", {len(samples.points[::every]):,} drawn" if every > 1 else "")
    return np.asarray(samples.points[::every], dtype=np.float64), attributes, run.surface.up_axis or "Z", note


def draw_input(path, views, size, sample_options):
    """((size, size * len(views), 3) uint8 picture, [caption line], legend) of one input
    (legend: [(label, rgb)] of the colours that say something, such as inside and outside)."""
    import numpy as np

    from ..writers.pointfiles import reason
    from .render import legend, point_colors, thumbnail

    try:
        points, attributes, up, note = load(path, sample_options)
    except ScatterError:
        raise
    except MemoryError:
        raise ScatterError(f"{path}: out of memory") from None
    except Exception as exc:  # a reader's or loader's own error type: one line, this input only
        raise ScatterError(f"{path}: {reason(exc)}") from None
    finite = np.isfinite(points).all(axis=1)
    if not finite.all():  # said in the caption, not dropped silently
        note += f", {int((~finite).sum()):,} not finite (not drawn)"
        points, attributes = points[finite], {k: v[finite] for k, v in attributes.items()}
    if len(points) == 0:
        raise ScatterError(f"{path}: no points" + (" with finite coordinates" if not finite.all() else ""))
    colors = point_colors(points, attributes, up)
    cut = "color" not in attributes and ("inside" in attributes or "sdf" in attributes)
    tile = np.concatenate([thumbnail(points, colors, v, up, size, cut=cut) for v in views], axis=1)
    return tile, [note], legend(attributes)


# ---- the sheet ----

class Sheet:
    """One page: thumbnails drawn into a NumPy canvas, captions and crosses drawn by
    Pillow when the page is written."""

    def __init__(self, cells, columns, size, views):
        import numpy as np

        from .render import BACKGROUND

        self.columns = min(columns, cells)
        self.size = size
        self.cell_w, self.cell_h = size * views, size + CAPTION
        rows = math.ceil(cells / self.columns)
        width = GAP + self.columns * (self.cell_w + GAP)
        height = GAP + rows * (self.cell_h + GAP)
        self.canvas = np.full((height, width, 3), BACKGROUND, dtype=np.uint8)
        self.texts = []  # (x, y, text, rgb)
        self.crosses = []  # (x0, y0, x1, y1)
        self.boxes = []  # (x0, y0, x1, y1) kept clear of the crosses, for the text over them

    def origin(self, slot):
        row, col = divmod(slot, self.columns)
        return GAP + col * (self.cell_w + GAP), GAP + row * (self.cell_h + GAP)

    def put(self, slot, tile, lines, legend=()):
        x, y = self.origin(slot)
        self.canvas[y : y + self.size, x : x + self.cell_w] = tile
        self.caption(x, y + self.size, lines)
        self.key(x, y, legend)

    def key(self, x, y, legend):
        """The legend [(label, rgb)] in the thumbnail's top-left corner, on a box of the
        background: a swatch and a label an entry."""
        if not legend:
            return
        from .render import BACKGROUND

        width = min(3 * 4 + SWATCH + CHAR * max(len(label) for label, _ in legend), self.cell_w)
        self.canvas[y : y + min(4 + LINE * len(legend), self.size), x : x + width] = BACKGROUND
        for i, (label, rgb) in enumerate(legend):
            top = y + 4 + i * LINE
            self.canvas[top + 2 : top + 2 + SWATCH, x + 4 : x + 4 + SWATCH] = rgb
            self.texts.append((x + 8 + SWATCH, top, label, TEXT_RGB))

    def failed(self, slot, path, message):
        x, y = self.origin(slot)
        self.canvas[y : y + self.size, x : x + self.cell_w] = FAILED_RGB
        self.crosses.append((x, y, x + self.cell_w - 1, y + self.size - 1))
        # the message in the top half, clear of the cross, which shows below it
        wrapped = wrap_lines(message, max(1, (self.cell_w - 8) // CHAR), max(1, (self.size // 2 - 4) // LINE))
        self.boxes.append((x, y, x + 5 + CHAR * max(map(len, wrapped)), y + 5 + LINE * len(wrapped)))
        for i, text in enumerate(wrapped):
            self.texts.append((x + 4, y + 4 + i * LINE, text, CROSS_RGB))
        self.caption(x, y + self.size, [path, "failed"])

    def caption(self, x, y, lines):
        chars = max(4, self.cell_w // CHAR)
        name = shorten(lines[0], chars)
        self.texts.append((x + 1, y + 2, name, TEXT_RGB))
        for i, text in enumerate(lines[1:], 1):
            self.texts.append((x + 1, y + 2 + i * LINE, shorten(text, chars), NOTE_RGB))

    def write(self, path):
        from ..writers import open_output

        Image, ImageDraw, ImageFont = image_module()
        picture = Image.fromarray(self.canvas, "RGB")
        draw = ImageDraw.Draw(picture)
        font = ImageFont.load_default_imagefont()  # the bitmap font: no FreeType, same pixels everywhere
        for x0, y0, x1, y1 in self.crosses:
            draw.line((x0, y0, x1, y1), fill=CROSS_RGB, width=3)
            draw.line((x0, y1, x1, y0), fill=CROSS_RGB, width=3)
        for box in self.boxes:
            draw.rectangle(box, fill=FAILED_RGB)
        for x, y, text, rgb in self.texts:
            draw.text((x, y), latin1(text), fill=rgb, font=font)
        buffer = io.BytesIO()
        picture.save(buffer, **PNG_OPTIONS)
        with open_output(path) as stream:
            stream.write(buffer.getvalue())


def wrap_lines(message, chars, rows):
    """``message`` in lines of at most ``chars`` characters broken between words (a word
    longer than a line, such as a path, is cut), at most ``rows`` of them: the last ends
    in "..." when the message goes on."""
    lines = textwrap.wrap(message, chars, break_on_hyphens=False) or [""]
    if len(lines) > rows:
        lines = lines[:rows]
        lines[-1] = lines[-1][: max(0, chars - 3)] + "..."
    return lines


def shorten(text, chars):
    """``text`` in at most ``chars`` characters, cut from the left ("...end of it")."""
    return text if len(text) <= chars else "..." + text[len(text) - chars + 3 :]


def latin1(text):
    """What the bitmap font can draw: other characters become '?'."""
    return text.encode("latin-1", "replace").decode("latin-1")


def summary(sheets) -> str:
    """One line on what failed, for standard error."""
    where = sheets[0] if len(sheets) == 1 else f"{len(sheets)} sheets"
    return f"preview: {len(sheets.failed)} of {sheets.inputs} inputs failed (crossed out on {where})"
