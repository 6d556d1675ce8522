"""The benchmarks live outside the shipped package (issue 31): a top-level ``benchmarks/``, still run as
``pfp bench NAME`` from a source checkout, and one line with exit 2 from an install without it."""

from __future__ import annotations

import shutil
import subprocess
import sys

import pytest

from tests.conftest import ROOT


@pytest.mark.unit
def test_the_service_package_holds_no_benchmarks():
    assert not (ROOT / "pfp_service" / "bench").exists()
    assert (ROOT / "benchmarks" / "__init__.py").is_file()


@pytest.mark.unit
def test_pfp_bench_finds_the_checkouts_benchmarks():
    from pfp_service.cli import build_parser

    args = build_parser().parse_args(["bench", "roundtrip", "--count", "3"])
    assert args.benchmark == "roundtrip" and args.count == 3 and callable(args.func)


@pytest.mark.proc
@pytest.mark.parametrize("args", [["bench", "engine", "--quick"], ["bench"]])
def test_without_a_checkout_pfp_bench_says_so_in_one_line(tmp_path, args):
    # an installed wheel: pfp_service alone, nothing beside it
    shutil.copytree(
        ROOT / "pfp_service", tmp_path / "pfp_service", ignore=shutil.ignore_patterns("__pycache__")
    )
    r = subprocess.run(
        [sys.executable, "-m", "pfp_service", *args],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=tmp_path,
        env={"PYTHONPATH": str(tmp_path), "PATH": "/usr/bin:/bin"},
    )
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("pfp bench: ") and "source checkout" in lines[0], r.stderr
