"""The options of a sample run: one frozen :class:`SampleOptions` and its one ``check()``.

``scatter sample``, ``scatter batch`` (and its workers, local or Dask) and the Python API
all build a :class:`SampleOptions` and call ``check()``, so they accept and refuse the same
option sets with the same messages. ``check()`` raises every usage error that holds
whatever the mesh (exit 2); what a mesh causes (an object name it lacks, a radius too
small for its area) is a failure of that mesh (:class:`~scatter_cli.errors.ScatterError`,
exit 1).

Standard library only: the command line imports this module for its defaults and
``--help`` before NumPy.
"""

from __future__ import annotations

import dataclasses
import decimal
import fractions
import math
import numbers
from dataclasses import dataclass

from ..errors import ScatterUsageError
from .fields import ATTRIBUTES

METHODS = ("random", "stratified", "sobol")
PRECISIONS = ("auto", "float32", "float64")
SIGNS = ("winding", "parity")
NORMALIZATIONS = ("none", "unit-cube", "unit-sphere")
DEFAULT_COUNT = 10_000
PADDING = 0.1  # --padding when not given
MAX_COUNT = 2**63 - 1  # the most points a run can number (its points are counted in int64)
# attributes that only a surface point has (usage errors with --volume)
SURFACE_ONLY = ("normal", "smooth-normal", "bary", "color", "uv", "orient")
# attributes that only a volume point has (usage errors without --volume)
VOLUME_ONLY = ("sdf", "inside", "winding", "closest")


@dataclass(frozen=True)
class SampleOptions:
    """Every option of a sample run, as ``scatter_cli.sample`` takes them (CLI.md).

    Built from keyword arguments, strings or lists as the command line and JSON give
    them: ``attributes`` ``"normal,face"`` or a sequence, ``objects`` a sequence,
    ``shard`` ``"K/M"`` or a pair, ``near`` ``"0.1,0.02"`` or a sequence; they are held
    as tuples. Nothing is checked until :meth:`check`.
    """

    count: int | None = None
    density: float | None = None
    seed: int = 0
    method: str = "random"
    attributes: tuple = ()
    poisson: bool = False
    radius: float | None = None
    weight: str | None = None
    objects: tuple | None = None
    precision: str = "auto"
    chunk_size: int | None = None
    stable: bool = False
    exterior: bool = False
    shard: tuple | None = None
    oversampling: float | None = None
    input_format: str | None = None
    volume: bool = False
    near: tuple | None = None
    box_share: float | None = None
    padding: float | None = None  # None: PADDING
    sign: str | None = None  # None: SIGNS[0], the winding number
    normalize: str = "none"
    edges: float | str = 0.0
    sharp_angle: float | None = None
    near_edges: tuple | None = None

    def __post_init__(self):
        def set_(name, value):
            object.__setattr__(self, name, value)

        set_("attributes", attribute_names(self.attributes))
        set_("count", whole_count(self.count))
        if self.objects is not None:  # one name, or a sequence of them
            set_("objects", (self.objects,) if isinstance(self.objects, str) else tuple(self.objects) or None)
        if self.shard is not None:
            set_("shard", _shard_pair(self.shard))
        if self.near is not None:
            set_("near", _numbers(self.near))
        if self.near_edges is not None:
            set_("near_edges", _numbers(self.near_edges))

    @classmethod
    def of(cls, values: dict) -> "SampleOptions":
        """The options among ``values`` (a dict with other keys too: a command's arguments)."""
        return cls(**{f.name: values[f.name] for f in dataclasses.fields(cls) if f.name in values})

    def as_dict(self) -> dict:
        """Keyword arguments (JSON-ready) that rebuild these options: ``SampleOptions(**d)``."""
        return {k: list(v) if isinstance(v, tuple) else v for k, v in dataclasses.asdict(self).items()}

    @property
    def thinned(self) -> bool:
        return self.poisson or self.radius is not None

    @property
    def volume_run(self) -> bool:
        """Points in space (``--volume``, or ``--near`` which implies it)."""
        return self.volume or self.near is not None

    @property
    def box_padding(self) -> float:
        """``--padding`` (PADDING when not given)."""
        return PADDING if self.padding is None else self.padding

    @property
    def sign_mode(self) -> str:
        """``--sign`` (the winding number when not given)."""
        return SIGNS[0] if self.sign is None else self.sign

    @property
    def edge_fraction(self) -> fractions.Fraction:
        """``--edges`` as the exact decimal it is written as (0.29 is 29/100); ValueError
        when it is not a number."""
        return edge_share(self.edges)

    @property
    def angle(self) -> float:
        """``--sharp-angle`` in degrees (15 when not given)."""
        from ..sampling.sharp import SHARP_ANGLE

        return SHARP_ANGLE if self.sharp_angle is None else float(self.sharp_angle)

    def check(self) -> "SampleOptions":
        """Raise ScatterUsageError for any option, or combination, that is wrong whatever
        the mesh; returns ``self``. (Checked once: a batch worker runs one set of options
        on every mesh.)"""
        if self.__dict__.get("_checked"):
            return self
        _check_numbers(self)
        check_attributes(self.attributes, self.volume_run)
        if self.weight:
            from ..sampling.weighting import parse_weight

            parse_weight(self.weight)
        _check_combinations(self)
        _check_edges(self)
        if self.volume_run:
            _check_volume(self)
        else:
            _check_surface(self)
        if self.count is not None:
            check_sobol_count(self.method, self.count)
            if self.poisson:
                from ..sampling.poisson.thinning import poisson_candidates

                poisson_candidates(self.count, self.oversampling, usage=True)
        object.__setattr__(self, "_checked", True)  # not a field: equality, as_dict and replace ignore it
        return self


def _check_numbers(o: SampleOptions):
    if o.count is not None and o.density is not None:
        raise ScatterUsageError("give either a count (-n) or a --density, not both")
    if o.count is not None and (not _is_int(o.count) or o.count < 0):
        raise ScatterUsageError(f"the count must be a non-negative integer, not {o.count!r}")
    if o.count is not None and o.count > MAX_COUNT:
        shown = f"{o.count:,}" if o.count < 10**30 else format(decimal.Decimal(o.count), ".3e")
        raise ScatterUsageError(f"the count {shown} is more than a run can number (at most 2^63 - 1 = {MAX_COUNT:,})")
    if o.density is not None and not (_is_real(o.density) and o.density > 0):
        raise ScatterUsageError(f"--density must be a positive number, not {o.density!r}")
    if not _is_int(o.seed) or o.seed < 0:
        raise ScatterUsageError(f"--seed must be a non-negative integer, not {o.seed!r}")
    _choice("method", o.method, METHODS)
    _choice("precision", o.precision, PRECISIONS)
    if o.chunk_size is not None and (not _is_int(o.chunk_size) or o.chunk_size < 1):
        raise ScatterUsageError(f"--chunk-size must be a positive integer, not {o.chunk_size!r}")
    if o.radius is not None and not (_is_real(o.radius) and o.radius > 0):
        raise ScatterUsageError(f"--radius must be a positive number, not {o.radius!r}")
    if o.oversampling is not None and not (_is_real(o.oversampling) and o.oversampling > 0):
        raise ScatterUsageError(f"oversampling must be a positive number, not {o.oversampling!r}")
    if isinstance(o.shard, str):
        raise ScatterUsageError(f"--shard must be K/M (shard K of M, 0-based), not {o.shard!r}")
    if o.shard is not None and not 0 <= o.shard[0] < o.shard[1]:
        raise ScatterUsageError(f"--shard K/M needs 0 <= K < M, not {o.shard[0]}/{o.shard[1]}")
    _choice("normalize", o.normalize, NORMALIZATIONS)


def _check_combinations(o: SampleOptions):
    if o.poisson and o.radius is not None:
        raise ScatterUsageError("give either --poisson (an exact count) or --radius, not both")
    if o.radius is not None and o.density is not None:
        raise ScatterUsageError("with --radius the count follows from R: drop --density")
    if o.method != "random" and (o.thinned or o.weight):
        raise ScatterUsageError(f"--method {o.method} does not combine with --poisson, --radius or --weight "
                                "(they work on the random method)")
    if o.stable and o.method != "random":
        raise ScatterUsageError(f"--stable does not combine with --method {o.method} (it is a random placement)")
    if o.stable and o.poisson:
        raise ScatterUsageError("--stable does not combine with --poisson (--radius gives a Poisson-disk set that "
                                "stays put)")
    if o.shard is not None and o.thinned:
        raise ScatterUsageError("--shard does not combine with --poisson or --radius (thinning is global)")


def _check_volume(o: SampleOptions):
    surface_only = [n for n, on in (("--poisson", o.poisson), ("--radius", o.radius is not None),
                                    ("--stable", o.stable), ("--exterior", o.exterior),
                                    (f"--method {o.method}", o.method != "random")) if on]
    if surface_only:
        raise ScatterUsageError(f"{', '.join(surface_only)} does not combine with --volume (surface runs only)")
    if o.near is not None and (isinstance(o.near, str) or not o.near or not all(_is_real(s) and s > 0 for s in o.near)):
        text = o.near if isinstance(o.near, str) else ",".join(map(str, o.near))
        raise ScatterUsageError(f"--near must be a comma list of positive standard deviations, not {text!r}")
    if o.box_share is not None and not (_is_real(o.box_share) and 0 <= o.box_share <= 1):
        raise ScatterUsageError(f"--box-share must be a number from 0 to 1, not {o.box_share!r}")
    if not (_is_real(o.box_padding) and o.box_padding >= 0):
        raise ScatterUsageError(f"--padding must be a number >= 0, not {o.padding!r}")
    _choice("sign", o.sign_mode, SIGNS)


def _check_surface(o: SampleOptions):
    """The options of a volume run, given to a surface run: they would be ignored."""
    given = [n for n, value in (("--box-share", o.box_share), ("--padding", o.padding), ("--sign", o.sign))
             if value is not None]
    if given:
        raise ScatterUsageError(f"{' and '.join(given)} {'is' if len(given) == 1 else 'are'} for volume runs only: "
                                "add --volume or --near")


def _check_edges(o: SampleOptions):
    try:
        share = o.edge_fraction
    except ValueError:
        share = None
    if share is None or not 0 <= share <= 1:
        raise ScatterUsageError(f"--edges must be a share from 0 to 1, not {o.edges!r}")
    if o.sharp_angle is not None and not (_is_real(o.sharp_angle) and 0 < o.sharp_angle <= 180):
        raise ScatterUsageError(f"--sharp-angle must be a number of degrees in (0, 180], not {o.sharp_angle!r}")
    if o.near_edges is not None and (isinstance(o.near_edges, str) or not o.near_edges
                                     or not all(_is_real(s) and s > 0 for s in o.near_edges)):
        text = o.near_edges if isinstance(o.near_edges, str) else ",".join(map(str, o.near_edges))
        raise ScatterUsageError(f"--near-edges must be a comma list of positive standard deviations, not {text!r}")
    if not share:
        given = [n for n, on in (("--sharp-angle", o.sharp_angle is not None), ("--near-edges", o.near_edges is not None))
                 if on]
        if given:
            raise ScatterUsageError(f"{' and '.join(given)} needs --edges F (the share of points on sharp edges)")
        return
    others = [n for n, on in (("--poisson", o.poisson), ("--radius", o.radius is not None), ("--stable", o.stable),
                              ("--exterior", o.exterior), (f"--method {o.method}", o.method != "random")) if on]
    if others:
        raise ScatterUsageError(f"--edges does not combine with {', '.join(others)}")
    if o.volume_run and o.near is None:
        raise ScatterUsageError("--edges with --volume needs --near (edge points are the surface points of near points)")
    if o.near_edges is not None and o.near is None:
        raise ScatterUsageError("--near-edges needs --near")


def edge_share(value) -> fractions.Fraction:
    """``--edges`` as the exact decimal it is written as: ``"0.29"`` or 0.29 -> 29/100 (a
    float stands for its shortest decimal form; None for 0). ValueError for what is not
    a number."""
    import decimal

    if value is None:
        return fractions.Fraction(0)
    if isinstance(value, bool) or not isinstance(value, (str, numbers.Real)):
        raise ValueError(f"{value!r} is not a number")
    text = repr(value) if isinstance(value, float) else str(value).strip()
    try:
        return fractions.Fraction(decimal.Decimal(text))
    except (decimal.InvalidOperation, ValueError, OverflowError):
        raise ValueError(f"{value!r} is not a number") from None


def check_attributes(names, volume=False):
    """Raise ScatterUsageError for unknown names, both normals, or names of the other kind
    of run (surface-only attributes with ``--volume``, volume-only without)."""
    unknown = [n for n in names if n not in ATTRIBUTES]
    if unknown:
        raise ScatterUsageError(f"unknown attribute {', '.join(map(repr, unknown))} (choose from: {', '.join(ATTRIBUTES)})")
    if "normal" in names and "smooth-normal" in names:
        raise ScatterUsageError("'normal' and 'smooth-normal' both write nx ny nz: ask for one of them")
    wrong = [n for n in names if n in (SURFACE_ONLY if volume else VOLUME_ONLY)]
    if wrong:
        kind = "surface" if volume else "volume"
        raise ScatterUsageError(f"attribute {', '.join(map(repr, wrong))} is for {kind} runs only"
                                + (" (drop --volume/--near)" if volume else " (add --volume)"))


def check_sobol_count(method, count, error=ScatterUsageError):
    """``--method sobol`` past 2^32 points: a usage error for a count given, ``error``
    (a failure of the mesh) for a ``--density`` count."""
    if method != "sobol":
        return
    from ..sampling.methods import SOBOL_MAX_COUNT  # (NumPy: only for sobol)

    if count > SOBOL_MAX_COUNT:
        raise error(f"--method sobol gives at most 2^32 = {SOBOL_MAX_COUNT:,} points per run, not {count:,}")


def attribute_names(text_or_list) -> tuple:
    """``"normal,face"`` or a sequence of names or of such lists (``-a`` repeated) -> the
    names, stripped, lower case, first occurrence kept."""
    if not text_or_list:
        return ()
    lists = [text_or_list] if isinstance(text_or_list, str) else list(text_or_list)
    items = [name for text in lists for name in str(text).split(",")]
    return tuple(dict.fromkeys(s.strip().lower() for s in items if s.strip()))


def whole_count(value):
    """A count as the Python API takes it: a float that is a whole number (``1e6``, as the
    command line takes it) as that integer; anything else as given (check() refuses it)."""
    if isinstance(value, float) and value.is_integer():
        return int(value)
    return value


def whole_number(text: str) -> int:
    """A count as a user types it: ``1000``, ``1e6``, ``2.5e3``; ValueError for ``1.5``."""
    if text.strip().isdigit():
        return int(text)
    import decimal  # exact: 1e20 is a whole number, 1.0000000000000001e3 is not

    try:
        value = decimal.Decimal(text.strip().replace("_", ""))
    except decimal.InvalidOperation:
        raise ValueError(f"{text!r} is not a number") from None
    if not value.is_finite() or value != value.to_integral_value():
        raise ValueError(f"{text!r} is not a whole number")
    return int(value)


def _shard_pair(shard):
    """``"K/M"`` or a pair -> (K, M) ints; a text that is neither stays as given (check() refuses it)."""
    try:
        k, m = (int(x) for x in (shard.split("/") if isinstance(shard, str) else shard))
    except (TypeError, ValueError):
        return shard if isinstance(shard, str) else str(shard)
    return k, m


def _numbers(values):
    """``"0.1,0.02"``, a sequence or one number -> tuple of floats; a text that is not stays as given."""
    items = values.split(",") if isinstance(values, str) else values
    if isinstance(items, numbers.Real):  # one sigma
        items = (items,)
    try:
        return tuple(float(v) for v in items)
    except (TypeError, ValueError):
        return values if isinstance(values, str) else str(values)


def _choice(name, value, choices):
    if value not in choices:
        raise ScatterUsageError(f"unknown {name} '{value}' (choose from: {', '.join(choices)})")


def _is_int(x) -> bool:
    return isinstance(x, numbers.Integral)  # NumPy's integers too


def _is_real(x) -> bool:
    return isinstance(x, numbers.Real) and math.isfinite(x)
