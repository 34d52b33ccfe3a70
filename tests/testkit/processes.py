"""The test's own processes: what a test started (and what those started, also after their
parent ended) and is still running.

The test process is made a child subreaper (Linux ``PR_SET_CHILD_SUBREAPER``, by
``conftest.py``), so a process orphaned by a command line the test ran (a campaign worker
whose parent exited) is re-parented to the test process instead of init: a leftover stays
inside the test's own process tree, and tests running in parallel never see each other's
processes.
"""
from __future__ import annotations

import ctypes
import os
import sys
from pathlib import Path

__all__ = ["become_subreaper", "descendants", "processes_mentioning"]

_PR_SET_CHILD_SUBREAPER = 36


def become_subreaper() -> bool:
    """Make this process the subreaper of its descendants (Linux only); True if it is."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        return ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def _stat(pid: str) -> tuple[int, str] | None:
    """(parent pid, state) of ``pid`` from /proc, or None if it is gone."""
    try:
        text = (Path("/proc") / pid / "stat").read_text()
    except OSError:
        return None
    rest = text[text.rfind(")") + 2:].split()      # the command name may hold spaces and parentheses
    return int(rest[1]), rest[0]


def descendants(root: int | None = None) -> list[int]:
    """The running (not zombie) processes below ``root`` (default: this process)."""
    root = os.getpid() if root is None else root
    children: dict[int, list[int]] = {}
    state: dict[int, str] = {}
    for d in Path("/proc").glob("[0-9]*"):
        info = _stat(d.name)
        if info is not None:
            children.setdefault(info[0], []).append(int(d.name))
            state[int(d.name)] = info[1]
    found, todo = [], list(children.get(root, []))
    while todo:
        pid = todo.pop()
        if state.get(pid) != "Z":
            found.append(pid)
        todo += children.get(pid, [])
    return sorted(found)


def processes_mentioning(text: str, root: int | None = None) -> list[int]:
    """The running processes below ``root`` (default: this process) whose command line
    contains ``text``."""
    found = []
    for pid in descendants(root):
        try:
            cmdline = (Path("/proc") / str(pid) / "cmdline").read_bytes().decode(errors="replace")
        except OSError:
            continue
        if text in cmdline.replace("\0", " "):
            found.append(pid)
    return found
