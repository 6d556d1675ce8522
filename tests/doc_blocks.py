"""Reading the docs' shell sessions: every ```sh and ```console block of README.md and docs/*.md as
commands (``Line``), which of them a test runs (``runnable``), and the files blocks write.

Read by ``tests/multi/test_docs.py``, which runs the blocks, and ``tests/unit/test_docs_in_process.py``.
"""

from __future__ import annotations

import re
import shlex
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
DOCS = [README, *sorted((ROOT / "docs").glob("*.md"))]
README_MAX_LINES = 300
DOC_PORT = "7447"

# What a person types around the commands; shown, never run here.
NOT_RUN = {"make", "pip", ".venv/bin/pip", "export", "source", "kill", "docker", "python3", "cd"}
PFP = {"pfp", ".venv/bin/pfp"}
PYTHON = {"python", ".venv/bin/python"}
# Commands that open a Zenoh session as a client of the planner (the shared flags).
SESSION = {"health", "status", "fleet", "inject", "map", "tak", "handheld"}


# -- reading the docs -------------------------------------------------------------------------------
@dataclass(frozen=True)
class Block:
    doc: Path
    line: int  # of the opening fence, 1-based
    lang: str
    text: str

    @property
    def name(self) -> str:
        return f"{self.doc.relative_to(ROOT)}:{self.line}"


def blocks(doc: Path) -> list[Block]:
    found: list[Block] = []
    lines = doc.read_text().splitlines()
    i = 0
    while i < len(lines):
        m = re.match(r"^```(\w*)\s*$", lines[i])
        if m:
            j = i + 1
            while j < len(lines) and not lines[j].startswith("```"):
                j += 1
            found.append(Block(doc, i + 1, m[1], "\n".join(lines[i + 1 : j])))
            i = j
        i += 1
    return found


@dataclass
class Line:
    words: list[str]  # the command, without environment assignments and "&"
    env: dict[str, str]
    background: bool
    text: str
    exit_code: int = 0  # what the doc says it exits with: "(exit N)" in its comment

    @property
    def program(self) -> str:
        return self.words[0] if self.words else ""

    @property
    def subcommand(self) -> str:
        return self.words[1] if self.program in PFP and len(self.words) > 1 else ""


def session_lines(block: Block) -> list[Line]:
    """The block's lines as commands: continuations joined, comments and blank lines dropped."""
    out: list[Line] = []
    for raw in block.text.replace("\\\n", " ").splitlines():
        if block.lang == "console":  # "$ command" lines; the rest is its output
            if not raw.startswith("$ "):
                continue
            raw = raw[2:]
        words = shlex.split(raw, comments=True)
        if not words:
            continue
        background = words[-1] == "&"
        if background:
            words = words[:-1]
        elif words[-1].endswith("&") and not words[-1].endswith("&&"):
            words[-1] = words[-1][:-1]
            background = True
        env: dict[str, str] = {}
        while words and re.match(r"^[A-Z_][A-Z0-9_]*=", words[0]):
            k, v = words.pop(0).split("=", 1)
            env[k] = v
        said = re.search(r"\(exit (\d+)\)", raw.partition(" #")[2])
        out.append(Line(words, env, background, raw.strip(), int(said[1]) if said else 0))
    return out


def runnable(line: Line) -> bool:
    """True for a line this test runs; False for one it shows only.

    Raises:
        AssertionError: a line it does not know what to do with.
    """
    if line.program in PFP or (line.program in PYTHON and line.words[1:2] and line.words[1].endswith(".py")):
        return True
    if line.program in NOT_RUN or line.program == "wait":
        return False
    raise AssertionError(f"a doc command this test cannot run or skip: {line.text!r}")


def sh_blocks() -> list[Block]:
    return [b for doc in DOCS for b in blocks(doc) if b.lang in ("sh", "console")]


def named_files() -> dict[str, str]:
    """``# NAME`` python and toml blocks: the files the sh blocks use."""
    files: dict[str, str] = {}
    for doc in DOCS:
        for b in blocks(doc):
            first = b.text.splitlines()[0] if b.text else ""
            m = re.match(r"^# ([\w.-]+\.(py|toml))\b", first)
            if b.lang in ("python", "toml") and m:
                assert m[1] not in files, f"{b.name}: {m[1]} is written twice in the docs"
                files[m[1]] = b.text + "\n"
    return files


def long_running(line: Line) -> bool:
    """Runs until stopped: it must come up and stay up."""
    sub = line.subcommand
    if sub in ("serve", "map", "tak", "handheld"):
        return True
    if sub == "fleet":
        return "--until-arrived" not in line.words and "--duration-s" not in line.words
    return line.program in PYTHON and line.background
