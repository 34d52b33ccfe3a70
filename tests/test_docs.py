"""The documentation builds nitpicky with no warning, with the command the developers page
gives; it documents every public name; its links resolve; and no user-facing text points at
issue numbers or files outside the repository."""
import importlib
import importlib.util
import inspect
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from testkit.docstrings import modules, public_objects

ROOT = Path(__file__).parents[1]
pytestmark = [pytest.mark.docs, pytest.mark.slow]
_spec = importlib.util.spec_from_file_location("doc_examples", ROOT / "docs" / "examples.py")
examples = importlib.util.module_from_spec(_spec)
sys.modules["doc_examples"] = examples
_spec.loader.exec_module(examples)


def _build_command() -> list[str]:
    """The documentation's build command as the developers page prints it, made strict."""
    block = next(b for b in examples.all_blocks() if b.name == "docs-build")
    args = shlex.split(block.code.strip())
    assert args[:5] == ["python", "-m", "sphinx", "-b", "html"], block.code
    return [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-n", "-q", *args[3:]]


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    pytest.importorskip("sphinx", reason="the documentation needs Sphinx and MyST (in the dev extra)")
    pytest.importorskip("myst_parser", reason="the documentation needs MyST (in the dev extra)")
    root = tmp_path_factory.mktemp("docs")
    shutil.copytree(ROOT / "docs", root / "docs", ignore=shutil.ignore_patterns("_build", "generated"))
    shutil.copy(ROOT / "CHANGELOG.md", root / "CHANGELOG.md")      # the changelog page includes it
    proc = subprocess.run(_build_command(), cwd=root, capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return root / "docs" / "_build"


def test_the_documentation_builds_without_warnings(built):
    for page in ("index", "install", "tutorial", "conventions", "guide/models", "api/index", "changelog",
                 "developers"):
        assert (built / f"{page}.html").exists(), page


def test_every_public_name_is_in_the_reference(built):
    from sphinx.util.inventory import InventoryFile

    with open(built / "objects.inv", "rb") as f:
        inv = InventoryFile.load(f, "", lambda base, uri: uri)
    documented = {name for kind in inv.values() for name in kind} if isinstance(inv, dict) else \
        {item.name for item in inv}
    missing = [q for q, _ in public_objects(private_modules=False) if q not in documented]
    assert not missing, f"not in the API reference: {missing}"


def test_the_changelog_page_is_the_changelog(built):
    text = (built / "changelog.html").read_text()
    assert "Unreleased" in text and "estimators.filter_fmu" in text


def test_the_built_pages_show_their_figures(built):
    """Every image a page shows is in the build (a missing one is a warning too)."""
    for page in ("tutorial", "guide/offline", "guide/experiments"):
        html = (built / f"{page}.html").read_text()
        for src in re.findall(r'<img [^>]*src="([^"]+)"', html):
            assert (built / page).parent.joinpath(src).resolve().exists(), (page, src)


def test_no_page_shows_raw_markup(built):
    """No role or directive is left unparsed (MyST parses a directive's rST output as
    Markdown unless it is wrapped in eval-rst, and says nothing)."""
    raw = re.compile(r":(?:py:)?(?:obj|class|func|meth|mod|data|attr|exc):`|\{py:|\{eval-rst\}|\.\. autosummary::")
    shown = [str(p.relative_to(built)) for p in built.rglob("*.html")
             if "_modules" not in p.parts and raw.search(p.read_text())]
    assert not shown, shown


# ---------------------------------------------------------------------- without building
_LINK = re.compile(r"\]\(([^)#\s]+)(?:#[^)]*)?\)")


def test_the_links_of_the_readme_and_the_pages_resolve():
    """Relative links (README into the guide, pages to each other, images) name files that
    exist; nothing links outside the repository by a relative path."""
    broken = []
    for page in examples.pages():
        for target in _LINK.findall(page.read_text()):
            if re.match(r"[a-z]+:", target):
                continue
            path = (page.parent / target).resolve()
            if not path.exists() or ROOT.resolve() not in path.parents:
                broken.append(f"{page.relative_to(ROOT)}: {target}")
    assert not broken, broken


#: What user-facing text must not say: issue numbers, internal goals, development-only files.
FORBIDDEN = re.compile(r"\bissues? \d+|issue \d+'s goal|\.\./shared|/work/shared|\bSPEC\b|SPEC\.md")


def _docstrings():
    for mod in modules():
        yield mod.__name__, inspect.getdoc(mod) or ""
        for name, obj in vars(mod).items():
            if getattr(obj, "__module__", None) != mod.__name__:
                continue
            if inspect.isclass(obj):
                yield f"{mod.__name__}.{name}", inspect.getdoc(obj) or ""
                for attr, member in vars(obj).items():
                    doc = inspect.getdoc(member) if callable(member) or isinstance(member, property) else None
                    if doc and not attr.startswith("__"):
                        yield f"{mod.__name__}.{name}.{attr}", doc
            elif inspect.isfunction(obj):
                yield f"{mod.__name__}.{name}", inspect.getdoc(obj) or ""


def test_user_facing_text_names_no_issue_or_outside_file():
    """Docstrings, the pages, the README, the shipped scenarios' comments and both command
    lines' help name no issue numbers, internal goals or files outside the repository."""
    found = [where for where, text in _docstrings() if FORBIDDEN.search(text)]
    found += [str(p.relative_to(ROOT)) for p in examples.pages() if FORBIDDEN.search(p.read_text())]
    found += [p.name for p in (ROOT / "cosim" / "scenarios").glob("*.toml") if FORBIDDEN.search(p.read_text())]
    from cosim.cli import build_parser

    parser = build_parser()
    helps = [parser.format_help()] + [sub.format_help() for action in parser._subparsers._group_actions
                                      for sub in action.choices.values()]
    proc = subprocess.run([sys.executable, "-m", "fmu_models", "build", "--help"], capture_output=True, text=True,
                          timeout=120)
    helps.append(proc.stdout)
    found += [f"help text {i}" for i, h in enumerate(helps) if FORBIDDEN.search(h)]
    assert not found, found


def _mini_build(tmp_path: Path, page: str) -> subprocess.CompletedProcess:
    """Build one page with the documentation's configuration (its resolver, nitpicky, -W)."""
    src = tmp_path / "src"
    (src / "_static").mkdir(parents=True)
    conf = (ROOT / "docs" / "conf.py").read_text()
    conf = conf.replace("ROOT = Path(__file__).resolve().parents[1]", f"ROOT = Path({str(ROOT)!r})")
    (src / "conf.py").write_text(conf)
    (src / "index.md").write_text(page)
    return subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-n", "-q", "-b", "html", str(src),
                           str(tmp_path / "out")], capture_output=True, text=True, timeout=600)


_DOCUMENTED = """# page

```{eval-rst}
.. py:function:: fmu_models.catalog.model_names()

   The one documented object of this page.
```
"""


def test_a_reference_resolves_to_what_it_names_in_python_or_fails_the_build(tmp_path):
    """The package's name (fmu_models.model_names) and the defining module's name reach the
    one documented object; a name that does not exist, one that exists but is not
    documented, and another project's name are warnings, so the build fails naming each."""
    proc = _mini_build(tmp_path, _DOCUMENTED + "{py:func}`fmu_models.model_names`, "
                                               "{py:func}`fmu_models.catalog.model_names`; "
                                               "{py:class}`estimators.NoSuchFilter`, {py:class}`estimators.UKF`, "
                                               "{py:func}`numpy.linalg.solve`\n")
    assert proc.returncode != 0
    for name in ("estimators.NoSuchFilter", "estimators.UKF", "numpy.linalg.solve"):
        assert f"reference target not found: {name}" in proc.stderr, proc.stderr
    assert proc.stderr.count("reference target not found") == 3, proc.stderr
    html = (tmp_path / "out" / "index.html").read_text()       # --keep-going: the page is written
    assert html.count('href="#fmu_models.catalog.model_names" title="fmu_models.catalog.model_names"') == 2
