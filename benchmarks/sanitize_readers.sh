#!/bin/sh
# The loader fuzzing with the compiled kernels built under AddressSanitizer and
# UndefinedBehaviorSanitizer (not for CI: slow, and it needs gcc's libasan).
#
#     sh benchmarks/sanitize_readers.sh [inputs]      (from the repository root)
#
# Builds a sanitized copy of the tree in a temporary directory, so the working tree's
# extensions stay as they are, then runs benchmarks/fuzz_loaders.py there with the ASan
# runtime preloaded. Any finding aborts the run with the sanitizer's report.
set -eu
PYTHON=${PYTHON:-/work/venv/bin/python}
INPUTS=${1:-20000}
ROOT=$(pwd)
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
cp -r scatter_cli tests benchmarks setup.py pyproject.toml README.md "$WORK"/
rm -f "$WORK"/scatter_cli/*.so
cd "$WORK"
SCATTER_SANITIZE=1 "$PYTHON" setup.py -q build_ext --inplace >/dev/null
ASAN=$(gcc -print-file-name=libasan.so)
# Python itself leaks by design at exit: leak checking off; every other error aborts.
LD_PRELOAD="$ASAN" ASAN_OPTIONS=detect_leaks=0:abort_on_error=1 \
    UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
    PYTHONPATH="$WORK" "$PYTHON" benchmarks/fuzz_loaders.py --inputs "$INPUTS" --save "$ROOT/fuzz-crashes"
