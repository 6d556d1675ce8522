"""``pfp demo --quick`` as a user runs it: it finishes by itself, prints the summary and writes the PNG."""

from __future__ import annotations

import re
import time

from tests.conftest import run_pfp


def test_demo_quick_runs_and_writes_summary_and_png(tmp_path):
    out = tmp_path / "demo.png"
    t0 = time.monotonic()
    r = run_pfp("demo", "--quick", "--out", str(out), timeout=120)
    took = time.monotonic() - t0
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    assert took < 60
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 20_000
    text = r.stdout
    assert "add threat e4" in text and "(when m2 at (" in text  # the mid-route contingency struck
    assert re.search(r"^t=\s*[\d.]+s \| m1 ", text, re.M)  # live progress lines
    header = "unit  kind      status   time s  path m  exposure  min clear m"
    assert header in text
    rows = [line.split() for line in text.split(header, 1)[1].splitlines()[1:7]]
    assert [row[0] for row in rows] == ["m1", "m2", "m3", "r1", "r2", "r3"]
    assert {row[1] for row in rows} == {"manned", "unmanned"}
    for row in rows:
        assert row[2] == "arrived"
        assert float(row[4]) > 40.0  # they crossed the box
        assert float(row[5]) >= 0.0
    assert "7/7 expectations held" in text


def test_demo_bad_script_is_one_line_exit_2(tmp_path):
    bad = tmp_path / "s.yaml"
    bad.write_text("timeline:\n  - {do: wait, seconds: -1}\n")
    r = run_pfp("demo", "--quick", "--script", str(bad), "--out", str(tmp_path / "x.png"), timeout=60)
    assert r.returncode == 2
    assert r.stderr.strip() == "pfp demo: s.yaml line 2, timeline[0].seconds: must be > 0"
