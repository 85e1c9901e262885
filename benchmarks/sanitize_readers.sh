#!/bin/sh
# The loader fuzzing with the compiled kernels built under AddressSanitizer and
# UndefinedBehaviorSanitizer (not for CI: slow, and it needs gcc's libasan).
#
#     sh benchmarks/sanitize_readers.sh [inputs [seed]]      (from the repository root)
#
# Builds a sanitized copy of the tree in a temporary directory, so the working tree's
# extensions stay as they are (a wheel built by pip with SCATTER_SANITIZE=1, its
# extensions unpacked into the copy), checks that the copy's readers are the sanitized
# build, then runs benchmarks/fuzz_loaders.py there with the ASan runtime preloaded.
# Any finding aborts the run with the sanitizer's report.
set -eu
ROOT=$(pwd)
PYTHON=${PYTHON:-$ROOT/.venv/bin/python}
INPUTS=${1:-20000}
SEED=${2:-0}
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
cp -r scatter_cli tests testkit benchmarks setup.py pyproject.toml README.md "$WORK"/
find "$WORK"/scatter_cli -name "*.so" -delete
SCATTER_SANITIZE=1 "$PYTHON" -m pip wheel -q --no-deps -w "$WORK/dist" "$WORK" >/dev/null
"$PYTHON" - "$WORK" <<'PY'
import glob, sys, zipfile
work = sys.argv[1]
wheel = zipfile.ZipFile(glob.glob(f"{work}/dist/*.whl")[0])
names = [n for n in wheel.namelist() if n.endswith(".so")]
assert any("_creaders" in n for n in names), names
for n in names:
    wheel.extract(n, work)
PY
ASAN=$(gcc -print-file-name=libasan.so)
cd "$WORK"
# Python itself leaks by design at exit: leak checking off; every other error aborts.
export LD_PRELOAD="$ASAN" ASAN_OPTIONS=detect_leaks=0:abort_on_error=1 \
    UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 PYTHONPATH="$WORK"
"$PYTHON" -c "
import scatter_cli.loading._creaders as c, subprocess
assert c.__file__.startswith('$WORK'), c.__file__
assert 'libasan' in subprocess.run(['ldd', c.__file__], capture_output=True, text=True).stdout, 'not a sanitized build'
print('sanitized readers:', c.__file__)"
"$PYTHON" benchmarks/fuzz_loaders.py --inputs "$INPUTS" --seed "$SEED" --save "$ROOT/fuzz-crashes"
