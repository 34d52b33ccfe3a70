"""The code examples of the documentation pages and the README, found and run as printed.

A runnable block is a fenced code block preceded by a marker line::

    <!-- test: NAME [FLAG ...] -->

(an HTML comment: invisible on GitHub and in the built pages). ``NAME`` is unique across
all pages. The languages are ``python`` and ``bash``; a block of any other language (a
scenario file, a plugin module) needs the flag ``writes=PATH`` and is written to ``PATH``
for the blocks after it. The flags:

``slow``, ``cross``
    the block takes minutes or needs the ``cross`` extra: its test carries the pytest
    marker of that name (outside the default run; ``python -m pytest -m "slow or cross"``);
``needs=reference-fmus``
    the Modelica Reference FMUs are copied into the folder first, those of FMI 2.0 into the
    folder itself and those of FMI 3.0 into ``fmi3/`` (their folder, holding ``fmi2/`` and
    ``fmi3/``, is named by ``PENDULUM_COSIM_REFERENCE_FMUS``; without it the test runs the
    page's blocks before the first block that needs them and skips the rest, saying so);
``checkout``
    the block runs in a copy of the repository (the set-up commands) instead of an empty
    folder;
``ci``
    the block is the continuous integration's test command: it is compared with what
    ``.ci/run`` runs, not run (the test suite cannot run itself);
``docs``
    the block builds the documentation: ``tests/test_docs.py`` runs it.

A page's blocks build on each other: they run in document order in one folder, every
Python block in one interpreter (one namespace), shell blocks in ``bash -euo pipefail``
with ``pendulum-cosim``, ``python`` and ``fmpy`` meaning this interpreter's. A ``slow`` or
``cross`` block runs after the page's other blocks that precede it. Unmarked blocks must
be ``text`` (output listings, not runnable); :func:`unmarked_code` finds any other.

Run one page by hand: ``python docs/examples.py docs/guide/offline.md [--all]`` (in a
temporary folder, printing what the blocks print; ``--all`` includes slow/cross blocks).
"""
from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LANGUAGES = ("python", "bash")
SEPARATOR = "\x1e"          # printed before each block's output: "\x1e<name>\n"
_FENCE = re.compile(r"^(?P<indent> {0,3})(?P<fence>`{3,}|~{3,})(?P<info>[^\n`]*)$")
#: MyST directives that show code: a plain fence is the way to show code (so the test sees it).
_CODE_DIRECTIVES = ("{code-block}", "{code}", "{code-cell}", "{sourcecode}")
_MARKER = re.compile(r"^<!-- test: (?P<name>[\w-]+)(?P<flags>(?: [\w=./-]+)*) -->$")


@dataclass
class Block:
    """One fenced code block of a page."""

    page: str                   # path relative to the repository root
    line: int                   # 1-based line of the opening fence
    language: str
    code: str
    name: str | None = None     # None: unmarked
    flags: dict = field(default_factory=dict)

    @property
    def marker(self) -> str | None:
        """The pytest marker the block's test carries (``slow``, ``cross``) or None."""
        return next((m for m in ("slow", "cross") if m in self.flags), None)


def pages() -> list[Path]:
    """The README and every Markdown page of ``docs/`` (not the build folder)."""
    docs = sorted(p for p in (ROOT / "docs").rglob("*.md") if "_build" not in p.parts)
    return [ROOT / "README.md", *docs]


def blocks(page: Path) -> list[Block]:
    """Every fenced code block of ``page``, with its marker if the line before has one."""
    lines = page.read_text(encoding="utf-8").splitlines()
    rel = str(page.relative_to(ROOT))
    found, i = [], 0
    while i < len(lines):
        m = _FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        fence, info = m["fence"], m["info"].strip()
        end = next((j for j in range(i + 1, len(lines))
                    if lines[j].strip().startswith(fence[0] * len(fence)) and not lines[j].strip().strip(fence[0])),
                   None)
        if end is None:
            raise ValueError(f"{rel}:{i + 1}: unclosed code block")
        language = info.split()[0] if info else ""
        if language.startswith("{") and language not in _CODE_DIRECTIVES:
            i = end + 1                 # a MyST directive (toctree, autosummary, ...): no code
            continue
        block = Block(rel, i + 1, language, "\n".join(lines[i + 1:end]) + "\n")
        marker = _MARKER.match(lines[i - 1].strip()) if i > 0 else None
        if marker:
            block.name = marker["name"]
            for flag in marker["flags"].split():
                key, _, value = flag.partition("=")
                block.flags[key] = value or True
        found.append(block)
        i = end + 1
    return found


def all_blocks() -> list[Block]:
    """The blocks of every page."""
    return [b for p in pages() for b in blocks(p)]


def unmarked_code() -> list[str]:
    """Where a block that is neither marked nor a ``text`` listing is (``page:line``)."""
    return [f"{b.page}:{b.line} ({b.language or 'no language'})" for b in all_blocks()
            if b.name is None and b.language != "text"]


def problems() -> list[str]:
    """Marked blocks that cannot run as marked: duplicate names, unknown flags, a block of
    another language without ``writes=``."""
    out, seen = [], {}
    known = {"slow", "cross", "needs", "checkout", "ci", "docs", "writes"}
    for b in all_blocks():
        if b.name is None:
            continue
        where = f"{b.page}:{b.line} ({b.name})"
        if b.name in seen:
            out.append(f"{where}: the name is also used at {seen[b.name]}")
        seen[b.name] = where
        if set(b.flags) - known:
            out.append(f"{where}: unknown flags {sorted(set(b.flags) - known)}")
        if b.language not in LANGUAGES and "writes" not in b.flags:
            out.append(f"{where}: a {b.language or 'plain'} block needs writes=PATH to be used")
        if b.flags.get("needs", "reference-fmus") != "reference-fmus":
            out.append(f"{where}: unknown need {b.flags['needs']!r}")
    return out


def runnable(page_blocks: list[Block]) -> list[list[Block]]:
    """The runs of one page: first every default block (document order), then one run per
    ``slow``/``cross`` block with the default blocks before it. ``ci`` and ``docs`` blocks
    are run elsewhere."""
    page_blocks = [b for b in page_blocks if b.name and "ci" not in b.flags and "docs" not in b.flags]
    default = [b for b in page_blocks if b.marker is None]
    runs = [default] if default else []
    for i, b in enumerate(page_blocks):
        if b.marker is not None:
            runs.append([d for d in page_blocks[:i] if d.marker is None] + [b])
    return runs


def reference_fmus() -> Path | None:
    """The folder of the Reference FMUs (``PENDULUM_COSIM_REFERENCE_FMUS``; it holds ``fmi2/``
    and ``fmi3/``), or None."""
    env = os.environ.get("PENDULUM_COSIM_REFERENCE_FMUS")
    folder = Path(env) if env else ROOT.parent / "shared" / "reference-fmus"
    return folder if (folder / "fmi2").is_dir() and (folder / "fmi3").is_dir() else None


def copy_checkout(dest: Path) -> Path:
    """A copy of the repository's own files in ``dest`` (no virtual environment, outputs or
    builds), for the blocks that run in a checkout."""
    skip = shutil.ignore_patterns(".git", ".venv", "out", "_build", "generated", "build", "dist", "*.egg-info",
                                  "__pycache__", ".pytest_cache", "*.fmu")
    shutil.copytree(ROOT, dest, ignore=skip)
    return dest


def _shims(folder: Path) -> Path:
    """``pendulum-cosim``, ``python``, ``python3`` and ``fmpy`` for this interpreter."""
    folder.mkdir(parents=True, exist_ok=True)
    py = sys.executable
    scripts = {"python": f'exec "{py}" "$@"', "python3": f'exec "{py}" "$@"',
               "pendulum-cosim": f'exec "{py}" -c "import sys; from cosim.cli import main; sys.exit(main())" "$@"',
               "fmpy": f'exec "{py}" -c "import sys; from fmpy.cli import main; sys.exit(main())" "$@"'}
    for name, body in scripts.items():
        path = folder / name
        path.write_text(f"#!/bin/sh\n{body}\n")
        path.chmod(0o755)
    return folder


def _driver(spec: Path) -> None:
    """Run the blocks listed in ``spec`` (JSON) in order, in the current folder: Python in
    this interpreter's one namespace, shell in bash, other languages written to their file."""
    todo = json.loads(spec.read_text())
    sys.path.insert(0, os.getcwd())     # as for code typed in this folder: its modules import
    namespace = {"__name__": "__main__"}
    for b in todo:
        print(f"{SEPARATOR}{b['name']}", flush=True)
        if "writes" in b["flags"]:
            Path(b["flags"]["writes"]).parent.mkdir(parents=True, exist_ok=True)
            Path(b["flags"]["writes"]).write_text(b["code"])
        elif b["language"] == "python":
            # padded so that a traceback's line numbers are the page's
            exec(compile("\n" * b["line"] + b["code"], b["page"], "exec"), namespace)
        else:
            proc = subprocess.run(["bash", "-euo", "pipefail", "-c", b["code"]], check=False)
            if proc.returncode != 0:
                sys.exit(f"{b['page']}:{b['line']} {b['name']}: the shell block exited with {proc.returncode}")
        sys.stdout.flush()


def run(todo: list[Block], cwd: Path, timeout: float = 1800) -> dict[str, str]:
    """Run ``todo`` in order in ``cwd`` (one interpreter); returns each block's output by name.

    Raises
    ------
    AssertionError
        A block failed: its page, line and name, and what it printed.
    """
    cwd.mkdir(parents=True, exist_ok=True)
    spec = Path(tempfile.mkdtemp(prefix="doc-examples-")) / "blocks.json"
    try:
        spec.write_text(json.dumps([vars(b) for b in todo]))
        if any(b.flags.get("needs") == "reference-fmus" for b in todo):
            (cwd / "fmi3").mkdir(exist_ok=True)
            for version, dest in (("fmi2", cwd), ("fmi3", cwd / "fmi3")):
                for fmu in sorted((reference_fmus() / version).glob("*.fmu")):
                    shutil.copy(fmu, dest / fmu.name)
        shims = _shims(spec.parent / "bin")
        env = {**os.environ, "MPLBACKEND": "Agg", "PATH": f"{shims}{os.pathsep}{os.environ.get('PATH', '')}",
               "PYTHONPATH": os.pathsep.join([str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])}
        proc = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--driver", str(spec)], cwd=cwd,
                              capture_output=True, text=True, env=env, timeout=timeout)
    finally:
        shutil.rmtree(spec.parent, ignore_errors=True)
    parts = proc.stdout.split(SEPARATOR)
    outputs = {}
    for part in parts[1:]:
        name, _, text = part.partition("\n")
        outputs[name] = text
    assert proc.returncode == 0, (f"the examples {[b.name for b in todo]} failed:\n{proc.stdout[-4000:]}\n"
                                  f"{proc.stderr[-6000:]}")
    return outputs


def _main(argv: list[str]) -> int:
    if argv[:1] == ["--driver"]:
        _driver(Path(argv[1]))
        return 0
    if not argv or argv[0] in ("-h", "--help"):
        print(__doc__)
        return 0
    page = Path(argv[0]).resolve()
    chosen = [b for b in blocks(page) if b.name and "ci" not in b.flags and "docs" not in b.flags
              and ("--all" in argv or b.marker is None)]
    folder = Path(tempfile.mkdtemp(prefix="doc-example-"))
    if any("checkout" in b.flags for b in chosen):
        folder = copy_checkout(folder / "checkout")
    for name, text in run(chosen, folder).items():
        print(f"--- {name}\n{text}", end="")
    print(f"(ran in {folder})")
    return 0


if __name__ == "__main__":
    sys.exit(_main(sys.argv[1:]))
