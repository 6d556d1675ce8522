"""``pfp serve``'s dispersion settings from the command line: a bad one is one line and exit 2."""

from __future__ import annotations

import pytest

from tests.conftest import run_pfp

pytestmark = pytest.mark.proc


def test_a_bad_class_in_the_config_is_one_line_and_exit_2(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('unit_class = {d1 = "hover"}\n')
    r = run_pfp("serve", "--config", str(bad), "--dispersion")
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert r.stderr.strip().splitlines() == [f"pfp serve: {bad}: unit_class[...]: unknown value 'hover'"]
