"""What a bench reads of a process tree from ``/proc``: CPU seconds, resident memory and PSS.

Every figure counts the whole tree a command starts (the planner, its preview
and deliberation workers, a fork server's children), as the benches report them.
"""

from __future__ import annotations

import os
from pathlib import Path


# -- CPU and resident memory -----------------------------------------------------------------------------
def _stat(pid: int) -> list[str] | None:
    """The fields of ``/proc/{pid}/stat`` after the command name (state first), ``None``: gone."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()
    except OSError:
        return None


def descendants(pid: int) -> list[int]:
    """Every live process below ``pid`` (its workers, a fork server's children), from ``/proc``."""
    children: dict[int, list[int]] = {}
    for name in os.listdir("/proc"):
        if name.isdigit() and (st := _stat(int(name))) is not None:
            children.setdefault(int(st[1]), []).append(int(name))
    out, todo = [], [pid]
    while todo:
        kids = children.get(todo.pop(), [])
        out += kids
        todo += kids
    return out


class ProcMeter:
    """CPU seconds and memory of one process from ``/proc`` (``None`` figures where there is none).

    ``cpu_s`` counts the whole tree: the process, every live descendant (the
    planner's deliberation and preview workers) and the children already
    reaped (``cutime``/``cstime``), so a responder's CPU is all it costs.
    """

    def __init__(self, pid: int, tree: bool = True) -> None:
        self.pid = pid
        self.tree = tree
        self._tick = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100

    def cpu_s(self) -> float | None:
        return self._cpu(self.cpu_by_process())

    def _cpu(self, each: dict[int, float] | None) -> float | None:
        return None if each is None else sum(each.values())

    def cpu_by_process(self) -> dict[int, float] | None:
        """CPU seconds of the process and (with ``tree``) of each descendant, reaped children in their parent's."""
        own = _stat(self.pid)
        if own is None:
            return None
        pids = descendants(self.pid) if self.tree else []
        out: dict[int, float] = {}
        for pid, st in [(self.pid, own), *((p, _stat(p)) for p in pids)]:
            if st is not None:  # utime + stime of every thread (+ cutime + cstime with the tree)
                ticks = int(st[11]) + int(st[12]) + (int(st[13]) + int(st[14]) if self.tree else 0)
                out[pid] = ticks / self._tick
        return out

    def processes(self) -> int:
        """How many processes the tree holds now (1 without ``tree``)."""
        return 1 + len(descendants(self.pid)) if self.tree else 1

    def memory_mb(self) -> dict[str, float | None]:
        """``rss_mb`` now and ``peak_rss_mb`` (VmHWM) since the process started."""
        out: dict[str, float | None] = {"rss_mb": None, "peak_rss_mb": None}
        try:
            with open(f"/proc/{self.pid}/status") as f:
                for line in f:
                    if line.startswith("VmRSS:"):
                        out["rss_mb"] = int(line.split()[1]) / 1024
                    elif line.startswith("VmHWM:"):
                        out["peak_rss_mb"] = int(line.split()[1]) / 1024
        except OSError:
            pass
        return out


def tree_pss_mb(pid: int) -> float:
    """The PSS of ``pid`` and all its descendants, in MB (``/proc/*/smaps_rollup``)."""
    return sum(tree_pss_by_process(pid).values())


def tree_pss_by_process(pid: int) -> dict[int, float]:
    """The PSS of ``pid`` and of each of its descendants, in MB, by process id."""
    out: dict[int, float] = {}
    for p in [pid, *descendants(pid)]:
        try:
            for line in Path(f"/proc/{p}/smaps_rollup").read_text().splitlines():
                if line.startswith("Pss:"):
                    out[p] = int(line.split()[1]) / 1024
                    break
        except OSError:
            continue
    return out
