"""The docs checked in process: the README stays under 300 lines and lists every command ``pfp --help``
shows, every relative link and anchor resolves, and the reach table of docs/algorithm.md is what the
threat model computes (split from ``test_docs``)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from tests.doc_blocks import (
    DOCS,
    PYTHON,
    README,
    README_MAX_LINES,
    ROOT,
    named_files,
    runnable,
    session_lines,
    sh_blocks,
)


# -- in process --------------------------------------------------------------------------------------
@pytest.mark.unit
def test_every_doc_line_is_run_or_known_to_be_shown():
    for block in sh_blocks():
        for line in session_lines(block):
            runnable(line)  # raises for a line it would neither run nor skip
            if line.program in PYTHON and line.words[1:2]:
                assert line.words[1] in named_files(), f"{block.name}: {line.words[1]} is not a doc file"


@pytest.mark.unit
def test_the_readme_is_a_first_hour_long():
    lines = README.read_text().splitlines()
    assert len(lines) <= README_MAX_LINES, f"README.md has {len(lines)} lines; move detail into docs/"


@pytest.mark.unit
def test_the_readme_command_table_lists_every_command():
    from pfp_service.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    commands = set(sub.choices)  # type: ignore[arg-type]
    bench = sub.choices["bench"]  # type: ignore[index]
    benchmarks = set(next(a for a in bench._actions if a.dest == "benchmark").choices)  # type: ignore[arg-type]
    table = [ln for ln in README.read_text().splitlines() if ln.startswith("| `pfp ")]
    shown = {re.match(r"^\| `pfp (\w+)", ln)[1] for ln in table}  # type: ignore[index]
    assert commands - shown == set(), f"commands missing from the README's table: {sorted(commands - shown)}"
    assert shown - commands == set(), (
        f"the README's table shows commands pfp lacks: {sorted(shown - commands)}"
    )
    bench_row = next(ln for ln in table if ln.startswith("| `pfp bench"))
    missing = {b for b in benchmarks if b not in bench_row}
    assert missing == set(), f"benchmarks missing from the README's table: {sorted(missing)}"


def _slug(heading: str) -> str:
    """GitHub's anchor for a heading."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


def _anchors(doc: Path) -> set[str]:
    text = re.sub(r"^```.*?^```", "", doc.read_text(), flags=re.S | re.M)
    return {_slug(m[1]) for m in re.finditer(r"^#{1,6} (.+)$", text, flags=re.M)}


@pytest.mark.unit
def test_every_relative_link_resolves():
    bad = []
    for doc in DOCS:
        text = re.sub(r"^```.*?^```", "", doc.read_text(), flags=re.S | re.M)
        for target in re.findall(r"\]\(([^)\s]+)\)", text):
            if re.match(r"^[a-z]+:", target):
                continue  # http(s), mailto: not checked here
            path, _, anchor = target.partition("#")
            dest = (doc.parent / path).resolve() if path else doc
            if not dest.exists():
                bad.append(f"{doc.name}: {target} (no such file)")
            elif anchor and dest.suffix == ".md" and anchor not in _anchors(dest):
                bad.append(f"{doc.name}: {target} (no such heading)")
    assert bad == []


@pytest.mark.unit
def test_the_vehicle_example_is_about_twenty_lines():
    files = named_files()
    assert "vehicle.py" in files
    code = [ln for ln in files["vehicle.py"].splitlines() if ln.strip() and not ln.startswith("#")]
    assert len(code) <= 22, f"the README's vehicle client grew to {len(code)} lines"


@pytest.mark.unit
def test_the_reach_table_is_what_the_threat_model_computes():
    """docs/algorithm.md's "Choosing sigma_range" table, recomputed from core.threat."""
    import numpy as np
    from scipy.optimize import brentq

    from pfp_service.core.threat import Threat, ThreatField

    text = (ROOT / "docs" / "algorithm.md").read_text()
    rows = re.findall(
        r"^\| (\d) \| ([\d.]+) \| ([\d.]+) \| ([\d.]+) \| ([\d.]+) \| ([\d.]+) / ([\d.]+) \|$", text, re.M
    )
    assert len(rows) == 5
    for skew, *shown in rows:
        threat = Threat.from_facing((0.0, 0.0), 0.0, 1.0, 0.6, float(skew))  # faces north, sigma_range 1
        field = ThreatField([threat], "peak")

        def level(x: float, y: float, f=field) -> float:
            return float(f.level(np.array([[x, y]]))[0])

        peak_y = threat.mode()[1]
        want = []
        for share in (0.1, 0.5):
            ahead = brentq(lambda y, s=share: level(0.0, y) - s, peak_y, 20.0)
            behind = -brentq(lambda y, s=share: level(0.0, y) - s, -20.0, peak_y)
            across = brentq(lambda x, s=share: level(x, peak_y) - s, 0.0, 20.0) / 0.6
            want.append((ahead, behind, across))
        (a10, b10, c10), (a50, b50, c50) = want
        expected = [a10, b10, a50, b50, c10, c50]
        for got, exp in zip(map(float, shown), expected):
            assert got == pytest.approx(exp, abs=0.006), f"skew {skew}: {shown} vs {expected}"


@pytest.mark.unit
def test_the_vehicle_example_speaks_the_wire_contract():
    """Its keys are templates of wire.keys, and the fields it writes and reads are the messages' own."""
    from pfp_service.wire import keys
    from pfp_service.wire.messages import Direction, Goal, UnitState

    code = named_files()["vehicle.py"]
    used = {
        k.replace("{M}", "{mission}").replace("{U}", "{unit}") for k in re.findall(r'f"(mumt/[^"]+)"', code)
    }
    templates = {keys.template(kind) for kind in keys.KeyKind}
    templates |= {
        keys.TEMPLATES[kind].replace("{id}", "*") for kind in keys.KeyKind
    }  # asked of every planner
    assert used and used <= templates, used - templates
    wrote = {
        UnitState: set(re.findall(r'"(\w+)":', code.split("state = ", 1)[1].splitlines()[0])),
        Goal: set(re.findall(r'"(\w+)":', code.split("/goal", 1)[1].splitlines()[0])),
        Direction: set(re.findall(r'd\["(\w+)"\]', code)),
    }
    for message, names in wrote.items():
        assert names and names <= set(message.__struct_fields__), (message.__name__, names)
