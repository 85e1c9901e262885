"""The pinned output bytes (tests/golden.py): every command's digest, with the compiled
kernels, on the NumPy path and with NumPy held to its baseline code, equals the one
committed in tests/golden_digests.json.

A change that must move bytes says so in its commit and updates only its own digests
(``python tests/golden.py --update``)."""

import json
import sys

import pytest

from tests.conftest import ROOT, numpy_baseline_env, run_user
from tests.golden import COMMANDS, DIGESTS


@pytest.mark.slow
@pytest.mark.parametrize("numpy_path, baseline", [(False, False), (True, False), (False, True)],
                         ids=["kernels", "numpy", "numpy-baseline"])
def test_every_command_writes_its_pinned_bytes(numpy_path, baseline, tmp_path):
    """numpy-baseline: NumPy held to its baseline code (no AVX2, no AVX-512), as on an older CPU."""
    # this tree's package, whatever PYTHONPATH or the installed copy say (the child runs elsewhere)
    env = {"SCATTER_NUMPY": "1" if numpy_path else "0", "PYTHONPATH": str(ROOT)}
    if baseline:
        env.update(numpy_baseline_env() or pytest.skip("NumPy dispatches no CPU feature beyond its baseline here"))
    proc = run_user([sys.executable, str(ROOT / "tests" / "golden.py")], env=env, cwd=tmp_path, timeout=600)
    assert proc.returncode == 0, proc.stderr.decode()
    got = json.loads(proc.stdout)
    pinned = json.loads(DIGESTS.read_text())
    assert sorted(got) == sorted(COMMANDS) == sorted(pinned)
    moved = {name for name in pinned if got[name] != pinned[name]}
    assert not moved, f"output bytes moved: {sorted(moved)}"


def test_the_digest_sees_one_byte(tmp_path):
    """The digest is not blind: one byte more in one output changes it."""
    from tests.golden import digest

    (tmp_path / "out.ply").write_bytes(b"ply\n")
    stdout = tmp_path / ".stdout"
    stdout.write_bytes(b"")
    before = digest(tmp_path, stdout)
    (tmp_path / "out.ply").write_bytes(b"ply\n\0")
    assert digest(tmp_path, stdout) != before
