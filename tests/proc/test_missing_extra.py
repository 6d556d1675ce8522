"""A command whose extra is not installed says, in one line, the pip install that fixes it (exit 2).

The venv of these tests has every extra, so each run hides one package the way
a plain install lacks it: ``sys.modules[name] = None`` makes its import fail
with ``ModuleNotFoundError`` before ``pfp`` starts, exactly as after ``make demo``.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from pfp_service.cli._common import pip_hint
from tests.zenoh_util import ROOT

# command line, the package hidden, the extra named
CASES = {
    "handheld": (["handheld", "--unit", "u1"], "textual", "tui"),
    "map": (["map"], "aiohttp", "map"),
    "demo": (["demo", "--quick"], "matplotlib", "demo"),
    "plan": (["plan", "examples/paper-simple.yaml", "--plot", "PNG"], "matplotlib", "plot"),
}
LINE = re.compile(
    r"^pfp (?P<cmd>\w+): needs the (?P<extra>\w+) extra: (?P<pip>\S+) install -e '\.\[(?P<e2>\w+)\]'$"
)


def _without(package: str, argv: list[str]) -> subprocess.CompletedProcess[str]:
    code = f"import sys; sys.modules[{package!r}] = None\nfrom pfp_service.cli import main\nsys.exit(main())"
    return subprocess.run(
        [sys.executable, "-c", code, *argv],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=ROOT,
        stdin=subprocess.DEVNULL,
    )


@pytest.mark.proc
@pytest.mark.parametrize("command", sorted(CASES))
def test_a_missing_extra_is_one_line_naming_the_venvs_pip(command, tmp_path):
    argv, package, extra = CASES[command]
    done = _without(package, [str(tmp_path / "out.png") if a == "PNG" else a for a in argv])
    assert done.returncode == 2, done.stdout + done.stderr
    lines = done.stderr.splitlines()
    assert len(lines) == 1, done.stderr  # no traceback, no doubled "pfp map: pfp map:"
    m = LINE.match(lines[0])
    assert m is not None, lines[0]
    assert (m["cmd"], m["extra"], m["e2"]) == (command, extra, extra)
    pip = ROOT / m["pip"]  # relative to the working directory, as a user types it there
    assert pip.exists() and pip.parent == Path(sys.executable).parent, m["pip"]
    assert not list(tmp_path.iterdir())  # refused before any work: no plot, no demo


@pytest.mark.unit
def test_the_hint_is_the_venvs_pip_and_this_checkout(monkeypatch, tmp_path):
    monkeypatch.chdir(ROOT)
    assert pip_hint("tui") == f"{Path(sys.executable).parent.relative_to(ROOT)}/pip install -e '.[tui]'"
    monkeypatch.chdir(tmp_path)  # elsewhere: both paths in full
    assert pip_hint("map") == f"{Path(sys.executable).parent}/pip install -e '{ROOT}[map]'"
