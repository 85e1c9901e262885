"""scatter_cli.core.elementary: log, sin, cos, atan2 and asin within 2 ulp of the C
library's, and the same bytes whatever code NumPy picks for the CPU; no output path
calls NumPy's own transcendental functions, whose last bits depend on it."""

import ast
import json
import math
import sys
from fractions import Fraction

import numpy as np
import pytest

from scatter_cli.core import elementary
from tests.conftest import ROOT, numpy_baseline_env, run_user


def ulps(got, ref):
    """(n,) errors of ``got`` in units of the last place of ``ref`` (its nonzero values)."""
    keep = ref != 0
    return np.abs(got[keep] - ref[keep]) / np.spacing(np.abs(ref[keep]))


def libm(function, x):
    return np.array([function(v) for v in np.asarray(x).tolist()])


RNG = np.random.default_rng(11)
UNIFORM = RNG.random(20000)


def test_log_is_within_one_ulp_of_the_c_librarys():
    x = np.concatenate([1.0 - UNIFORM, np.exp(RNG.uniform(-740, 709, 20000)), [1.0, 0.5, 2.0, 5e-324, 1.7e308]])
    assert ulps(elementary.log(x), libm(math.log, x)).max() <= 1.0
    with np.errstate(all="raise"):  # (no warning for the special values)
        special = elementary.log(np.array([1.0, 0.0, np.inf, -1.0, np.nan]))
    assert special[:3].tolist() == [0.0, -np.inf, np.inf] and np.isnan(special[3:]).all()


def split(value, bits):
    """``value`` (a Fraction) rounded to a double of ``bits`` significant bits."""
    m, e = math.frexp(float(value))
    return math.ldexp(round(math.ldexp(m, bits)), e - bits)


def test_the_written_constants_are_the_derived_ones():
    pio2 = Fraction("1.57079632679489661923132169163975144209858469968755291048747")
    ln2 = Fraction("0.693147180559945309417232121458176568075500134360255254120680")
    p1 = split(pio2, 33)
    p2 = split(pio2 - Fraction(p1), 33)
    assert (elementary.PIO2_1, elementary.PIO2_2) == (p1, p2)
    assert elementary.PIO2_3 == float(pio2 - Fraction(p1) - Fraction(p2))
    assert elementary.TWO_OVER_PI == float(1 / pio2)
    assert elementary.LN2_HI == split(ln2, 40) and elementary.LN2_LO == float(ln2 - Fraction(split(ln2, 40)))
    assert elementary.SIN_TERMS == tuple(float(Fraction((-1) ** k, math.factorial(2 * k + 1))) for k in range(8, 0, -1))
    assert elementary.COS_TERMS == tuple(float(Fraction((-1) ** k, math.factorial(2 * k))) for k in range(9, 1, -1))
    assert elementary.LOG_TERMS == tuple(float(Fraction(2, 2 * k + 1)) for k in range(11, 0, -1))
    assert elementary.SQRT_HALF == float(math.sqrt(0.5))


def sine_cosine_ulps(t):
    """The greatest errors (ulp) of elementary's sine and cosine of ``t`` (n,) against the C library's."""
    s, c = elementary.sincos(t)
    assert np.array_equal(s, elementary.sin(t)) and np.array_equal(c, elementary.cos(t))
    return ulps(s, libm(math.sin, t)).max(), ulps(c, libm(math.cos, t)).max()


ANGLES = np.concatenate([2 * math.pi * UNIFORM, RNG.uniform(-1e5, 1e5, 20000), [0.0, -0.0, 1e-300, math.pi / 4]])


def test_sine_and_cosine_are_within_two_ulp_of_the_c_librarys():
    assert max(sine_cosine_ulps(ANGLES)) <= 2.0
    with np.errstate(all="raise"):
        assert np.isnan(elementary.sincos(np.array([np.inf, -np.inf, np.nan]))).all()


def test_a_reduction_by_pi_over_two_in_one_double_would_not_be(monkeypatch):
    """The failing twin: pi/2 as one double, not three parts (large angles lose bits)."""
    monkeypatch.setattr(elementary, "PIO2_1", math.pi / 2)
    monkeypatch.setattr(elementary, "PIO2_2", 0.0)
    monkeypatch.setattr(elementary, "PIO2_3", 0.0)
    assert max(sine_cosine_ulps(ANGLES)) > 100


def test_arctangent_and_arcsine_are_within_two_ulp_of_the_c_librarys():
    y = np.concatenate([RNG.normal(size=20000) * 10.0 ** RNG.integers(-8, 8, 20000), [0.0, 1.0, -1.0, 0.0, 5.0]])
    x = np.concatenate([RNG.normal(size=20000) * 10.0 ** RNG.integers(-8, 8, 20000), [1.0, 0.0, 0.0, -1.0, np.inf]])
    assert ulps(elementary.atan2(y, x), np.arctan2(y, x)).max() <= 2.0
    assert np.isnan(elementary.atan2(np.array([np.nan, 1.0]), np.array([1.0, np.nan]))).all()
    a = np.concatenate([RNG.uniform(-1, 1, 20000), [1.0, -1.0, 0.0, 1 - 2**-53, 1e-300]])
    assert ulps(elementary.asin(a), libm(math.asin, a)).max() <= 2.0


# -- the same bytes whatever NumPy's dispatch ------------------------------------------

DIGESTS = """
import hashlib, json, sys
import numpy as np
from scatter_cli.core import elementary as el
from scatter_cli.api import sample
u = np.random.default_rng(3).random(100000)
t = 2 * np.pi * u - np.pi
out = {"log": el.log(1 - u), "sincos": np.concatenate(el.sincos(40 * t)), "atan2": el.atan2(t, u - 0.5),
       "asin": el.asin(2 * u - 1), "numpy-log1p": np.log1p(-u), "numpy-arcsin": np.arcsin(2 * u - 1),
       "numpy-arctan2": np.arctan2(t, u - 0.5)}
runs = {"near": dict(near=(0.02, 0.001), attributes="sdf"), "weights": dict(weight="vertex-color:r"),
        "orient": dict(attributes="orient,smooth-normal"), "edges": dict(edges=0.5, attributes="sharp")}
for name, options in runs.items():
    mesh = sys.argv[2] if name == "weights" else sys.argv[1]
    s = sample(mesh, count=3000, seed=9, precision="float64", **options)
    out[name] = np.concatenate([s.points.ravel()] + [np.asarray(v, dtype=np.float64).ravel() for v in s.attributes.values()])
print(json.dumps({k: hashlib.sha256(np.ascontiguousarray(v).tobytes()).hexdigest() for k, v in out.items()}))
"""


@pytest.fixture(scope="module")
def digests_both_ways():
    """The digests of DIGESTS' arrays under NumPy's full dispatch and under its baseline."""
    off = numpy_baseline_env()
    if not off:
        pytest.skip("NumPy dispatches no CPU feature beyond its baseline here")
    argv = [sys.executable, "-c", DIGESTS, str(ROOT / "samples" / "spot_triangulated.obj"),
            str(ROOT / "samples" / "boxvertexcolors.glb")]
    got = []
    for env in ({"PYTHONPATH": str(ROOT)}, {"PYTHONPATH": str(ROOT), **off}):
        proc = run_user(argv, env=env, timeout=300)
        assert proc.returncode == 0, proc.stderr.decode()
        got.append(json.loads(proc.stdout))
    return got


def test_scatters_functions_and_outputs_are_the_same_bytes_whatever_numpys_dispatch(digests_both_ways):
    full, base = digests_both_ways
    moved = sorted(k for k in full if not k.startswith("numpy-") and full[k] != base[k])
    assert not moved


def test_numpys_own_functions_would_not_be(digests_both_ways):
    """The failing twin, where the CPU has what NumPy dispatches to (AVX-512 here)."""
    full, base = digests_both_ways
    if all(full[k] == base[k] for k in full if k.startswith("numpy-")):
        pytest.skip("NumPy's log1p, arcsin and arctan2 give the same bytes on this CPU's code paths")
    assert any(full[k] != base[k] for k in full if k.startswith("numpy-"))


# -- no output path calls NumPy's transcendental functions -----------------------------

TRANSCENDENTAL = {"log", "log1p", "log2", "log10", "exp", "expm1", "exp2", "sin", "cos", "tan", "arcsin", "arccos",
                  "arctan", "arctan2", "sinh", "cosh", "tanh", "arcsinh", "arccosh", "arctanh", "power",
                  "float_power", "cbrt", "hypot", "logaddexp", "logaddexp2"}
# where their last bits reach no output: a test function, fits of a report's slopes, a picture's splats
ALLOWED = {"stats/measures.py": {"exp", "sin", "cos"}, "commands/bench.py": {"log10"},
           "commands/render.py": {"hypot"}, "loading/usd.py": {"hypot"}}


def numpy_transcendentals(source: str) -> set:
    """The names in TRANSCENDENTAL called as ``np.NAME`` or ``numpy.NAME`` in ``source``."""
    found = set()
    for node in ast.walk(ast.parse(source)):
        if (isinstance(node, ast.Attribute) and node.attr in TRANSCENDENTAL and isinstance(node.value, ast.Name)
                and node.value.id in ("np", "numpy")):
            found.add(node.attr)
    return found


def test_no_output_path_calls_numpys_transcendental_functions():
    package = ROOT / "scatter_cli"
    calls = {p.relative_to(package).as_posix(): numpy_transcendentals(p.read_text()) for p in package.rglob("*.py")}
    assert {name: sorted(found - ALLOWED.get(name, set())) for name, found in calls.items()
            if found - ALLOWED.get(name, set())} == {}


def test_the_scan_sees_a_call():
    assert numpy_transcendentals("import numpy as np\nr = np.sqrt(-2 * np.log1p(-u))\n") == {"log1p"}
    assert numpy_transcendentals("r = np.sqrt(x) + elementary.log(y)\n") == set()
