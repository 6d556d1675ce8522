"""Compiled kernels are cached per version of their sources, never loaded stale after another file changed."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from pfp_service import _numba_cache_dir
from tests.conftest import ROOT


@pytest.mark.unit
def test_the_cache_directory_follows_every_compiled_modules_source(tmp_path):
    (tmp_path / "core").mkdir()
    (tmp_path / "terrain").mkdir()
    kernels, steprule = tmp_path / "core" / "kernels.py", tmp_path / "core" / "steprule.py"
    kernels.write_text("def term(x): return x\n")
    steprule.write_text("def judge(x): return term(x)\n")
    first = _numba_cache_dir(str(tmp_path))
    assert first is not None and first == _numba_cache_dir(str(tmp_path))  # stable
    kernels.write_text("def term(x): return 2 * x\n")  # only the inlined callee's file changes
    second = _numba_cache_dir(str(tmp_path))
    assert second != first
    (tmp_path / "terrain" / "viewshed.py").write_text("x = 1\n")
    assert _numba_cache_dir(str(tmp_path)) not in (first, second)


@pytest.mark.proc
def test_numba_reads_it_and_a_users_own_choice_wins(tmp_path):
    code = "import pfp_service, numba; print(numba.config.CACHE_DIR)"
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    r = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, env=env, timeout=120
    )
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == _numba_cache_dir()
    env["NUMBA_CACHE_DIR"] = str(tmp_path)
    r = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, env=env, timeout=120
    )
    assert r.stdout.strip() == str(tmp_path)
