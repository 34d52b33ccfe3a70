"""Every code example of the README and of the documentation pages runs as printed.

The examples are the fenced blocks marked ``<!-- test: NAME [FLAGS] -->`` (found and run by
``docs/examples.py``, which documents the flags): a page's blocks run in document order in
one temporary folder, its Python blocks in one interpreter. Some examples carry a claim
the page makes in words; the checks below hold them to it.
"""
import importlib.util
import re
import shlex
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).parents[1]
_spec = importlib.util.spec_from_file_location("doc_examples", ROOT / "docs" / "examples.py")
examples = importlib.util.module_from_spec(_spec)
sys.modules["doc_examples"] = examples
_spec.loader.exec_module(examples)


def _numbers(text: str) -> list[float]:
    return [float(v) for v in re.findall(r"-?\d+\.\d+(?:e[-+]?\d+)?", text)]


# ------------------------------------------------------------------ what examples claim
def _offline(outputs: dict, cwd: Path) -> None:
    """EM learns q and r to 5 % from 100x too large; the smoother beats the filter."""
    out = outputs["offline"]
    q, r = map(float, re.search(r"learned q = (\S+), r = (\S+) in", out).groups())
    assert q == pytest.approx(1e-3, rel=0.05) and r == pytest.approx(1e-3, rel=0.05)
    filt, smooth = (_numbers(line.split(":")[1]) for line in out.splitlines()[1:3])
    assert len(filt) == len(smooth) == 4 and all(s < f for s, f in zip(smooth, filt))
    assert (cwd / "filter_smoother_truth.png").stat().st_size > 10_000


def _another_tool_loop(outputs: dict, cwd: Path) -> None:
    """The estimator FMU in a bare fmpy loop gives the Python EKF's estimates."""
    assert float(outputs["another-tool-loop"].split("largest difference:")[1]) < 1e-12


def _platforms(outputs: dict, cwd: Path) -> None:
    """Every FMU of the SSP carries the binaries of the three desktop platforms."""
    import zipfile

    with zipfile.ZipFile(cwd / "loop_ssp_all" / "seed000_cartpole.ssp") as z:
        fmus = [n for n in z.namelist() if n.endswith(".fmu")]
        assert len(fmus) == 6
        for n in fmus:
            (cwd / "one.fmu").write_bytes(z.read(n))
            with zipfile.ZipFile(cwd / "one.fmu") as f:
                folders = {m.split("/")[1] for m in f.namelist() if m.startswith("binaries/")}
            assert folders == {"linux64", "win64", "darwin64"}, n


def _tutorial_compare(outputs: dict, cwd: Path) -> None:
    """The EKF on the mismatched record is overconfident (mean NIS above 3 for ny = 2); the
    fading-memory EKF is consistent and has a smaller error in every state."""
    *ekf, ekf_nis = _numbers(outputs["tutorial-ekf"])
    *fading, fading_nis = _numbers(outputs["tutorial-compare"])
    assert ekf_nis > 3 and 1.5 < fading_nis < 2.5
    assert len(ekf) == len(fading) == 4 and all(f < e for f, e in zip(fading, ekf))
    assert (cwd / "tutorial_fading.png").stat().st_size > 10_000


def _tutorial_fmu(outputs: dict, cwd: Path) -> None:
    """The exported FMU gives the Python filter's estimates; the component equals ``run``."""
    fmu, component = map(float, re.findall(r": (\S+?)[;\n]", outputs["tutorial-fmu-check"] + "\n"))
    assert fmu < 1e-12 and component < 1e-12


def _adaptive_filter(outputs: dict, cwd: Path) -> None:
    """The filter that learns r finds the true 1e-3 from 0.1 within 20 %."""
    found = re.search(r"after \d+ steps (\S+)", outputs["writing-an-adaptive-filter-run"]).group(1)
    assert float(found) == pytest.approx(1e-3, rel=0.2)


def _me_system(outputs: dict, cwd: Path) -> None:
    """One ME system is exact to the solver's tolerance; separate components are not."""
    lines = outputs["me-system-check"].splitlines()[:2]
    joint, separate = (float(re.search(r"position (\S+) m", line).group(1)) for line in lines)
    assert joint < 1e-4 < 1e-2 < separate


def _isolated(outputs: dict, cwd: Path) -> None:
    """An isolated FMU gives the in-process results exactly."""
    assert float(outputs["third-party-isolated"]) == 0.0


def _figure(name: str):
    def check(outputs: dict, cwd: Path) -> None:
        assert (cwd / name).stat().st_size > 10_000
    check.__doc__ = f"the example writes {name}"
    return check


def _demo(outputs: dict, cwd: Path) -> None:
    """The demo writes its files and prints the error table."""
    for name in ("results.csv", "results.parquet", "rmse.csv", "truth_vs_estimate.png"):
        assert (cwd / "out" / "demo" / name).stat().st_size > 0
    assert "RMSE against the plant's true states" in outputs["demo"]


CHECKS = {"offline": _offline, "another-tool-loop": _another_tool_loop, "another-tool-platforms": _platforms,
          "tutorial-compare": _tutorial_compare, "tutorial-fmu-check": _tutorial_fmu,
          "writing-an-adaptive-filter-run": _adaptive_filter, "me-system-check": _me_system,
          "third-party-isolated": _isolated, "readme-example": _figure("estimate.png"), "demo": _demo,
          "setup-demo": _figure("out/demo/truth_vs_estimate.png")}


# ------------------------------------------------------------------ the runs
#: Pages whose default examples build FMUs and run the command line on scenarios (several
#: seconds each): run with the slow tests; the README's, the tutorial's and the smaller
#: pages' examples stay in the default run.
SLOW_PAGES = {"docs/guide/cosimulation.md", "docs/guide/another-tool.md", "docs/guide/extending.md",
              "docs/guide/reliability.md", "docs/guide/third-party-fmus.md", "docs/guide/clocks.md",
              "docs/tutorial.md", "docs/tutorial-fmu.md", "docs/guide/offline.md", "docs/guide/writing-a-filter.md"}

def _cases():
    cases = []
    for page in examples.pages():
        rel = str(page.relative_to(ROOT))
        for todo in examples.runnable(examples.blocks(page)):
            last = todo[-1]
            marks = [getattr(pytest.mark, last.marker)] if last.marker else []
            if last.marker is None and rel in SLOW_PAGES:
                marks.append(pytest.mark.slow)
            ident = rel if last.marker is None else f"{rel}::{last.name}"
            cases.append(pytest.param(todo, id=ident, marks=marks))
    return cases


def run_block(todo, cwd: Path) -> dict:
    """Run the blocks ``todo`` in ``cwd``; their outputs by name."""
    return examples.run(todo, cwd)


@pytest.mark.parametrize("todo", _cases())
def test_the_examples_of_a_page_run(todo, tmp_path):
    """A page's blocks run in order; without the Reference FMUs, those before the first block
    that needs them run, and the test skips the rest, saying so."""
    if todo[-1].marker == "cross" and not all(importlib.util.find_spec(m) for m in ("ziglang", "lief")):
        pytest.skip("the cross extra (ziglang, lief) is not installed: pip install -e '.[cross]'")
    needs = [i for i, b in enumerate(todo) if b.flags.get("needs") == "reference-fmus"]
    todo, left = (todo[:needs[0]], todo[needs[0]:]) if needs and examples.reference_fmus() is None else (todo, [])
    absent = "the Modelica Reference FMUs are absent: PENDULUM_COSIM_REFERENCE_FMUS names their folder"
    if not todo:
        pytest.skip(absent)
    cwd = examples.copy_checkout(tmp_path / "checkout") if any("checkout" in b.flags for b in todo) else tmp_path
    outputs = run_block(todo, cwd)
    for b in todo:
        if b.name in CHECKS:
            CHECKS[b.name](outputs, cwd)
    if left:
        pytest.skip(f"{absent}; not run: {[b.name for b in left]}")


# ------------------------------------------------------------------ the pages as a whole
def test_every_code_block_is_run_or_a_listing():
    """A code block is marked (and so run) or a ``text`` listing, never unchecked code."""
    assert not examples.unmarked_code(), examples.unmarked_code()


def test_every_marked_block_can_run_as_marked():
    assert not examples.problems(), examples.problems()


def test_every_check_has_its_example():
    names = {b.name for b in examples.all_blocks()}
    assert set(CHECKS) <= names, set(CHECKS) - names
    assert all(b.name in names for b in examples.all_blocks() if "docs" in b.flags)


def test_every_page_of_the_guide_shows_runnable_code_or_says_why():
    """The guide's pages that teach an API carry runnable examples."""
    teaching = ["tutorial.md", "guide/models.md", "guide/plant-fmus.md", "guide/estimators.md",
                "guide/writing-a-filter.md", "guide/offline.md", "guide/cosimulation.md", "guide/clocks.md",
                "guide/third-party-fmus.md", "guide/another-tool.md", "guide/extending.md",
                "guide/reliability.md", "guide/experiments.md"]
    for page in teaching:
        assert any(b.name for b in examples.blocks(ROOT / "docs" / page)), page


def test_the_readme_starts_with_the_two_set_up_commands():
    """The first two code blocks of the README, before any section: install and demo from
    the wheel (not editable), then the dev extra and the tests."""
    readme = (ROOT / "README.md").read_text()
    head = readme.split("\n## ")[0]
    first = [b for b in examples.blocks(ROOT / "README.md")][:2]
    assert [b.name for b in first] == ["setup-demo", "setup-tests"]
    assert all(f"<!-- test: {b.name}" in head for b in first)
    demo, tests = (b.code.strip() for b in first)
    assert "pip install . " in demo and "-e" not in demo and demo.endswith("pendulum-cosim demo")
    assert tests.endswith("python -m pytest -q") and "'.[dev]'" in tests
    assert len(readme.splitlines()) <= 250


def test_the_readme_test_command_is_what_the_ci_runs():
    """Each command of the README's second set-up line is a line of ``.ci/run`` (pip's
    ``-q`` aside): the suite cannot run itself, so this is how the command is checked."""
    block = next(b for b in examples.blocks(ROOT / "README.md") if b.name == "setup-tests")
    assert "ci" in block.flags

    def norm(cmd: str) -> list[str]:
        return [w for w in shlex.split(cmd) if w != "-q" or not cmd.startswith("pip")]

    script = (ROOT / ".ci" / "run").read_text().replace("\\\n", " ")      # continued lines joined
    ci = [norm(line.strip()) for line in script.splitlines() if line.strip() and not line.lstrip().startswith("#")]
    for command in block.code.strip().split("&&"):
        assert norm(command.strip()) in ci, f"{command.strip()!r} is not what .ci/run runs"


def test_the_readme_figure_is_the_example_s():
    """The README shows the figure its example makes (committed by docs/make_figures.py)."""
    readme = (ROOT / "README.md").read_text()
    assert "docs/_static/readme_estimate.png" in readme
    image = ROOT / "docs" / "_static" / "readme_estimate.png"
    assert image.stat().st_size > 10_000 and image.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


# ------------------------------------------------------------------ the runner itself, abused
def _page(tmp_path: Path, text: str) -> Path:
    page = tmp_path / "page.md"
    page.write_text(text)
    return page


def test_an_unmarked_code_block_is_found(tmp_path, monkeypatch):
    page = _page(tmp_path, "# t\n\n```python\nprint(1)\n```\n\n```text\nlisting\n```\n\n```{toctree}\nx\n```\n")
    monkeypatch.setattr(examples, "ROOT", tmp_path)
    monkeypatch.setattr(examples, "pages", lambda: [page])
    assert examples.unmarked_code() == ["page.md:3 (python)"]


def test_code_shown_through_a_directive_is_found(tmp_path, monkeypatch):
    page = _page(tmp_path, "```{code-block} python\nprint(1)\n```\n")
    monkeypatch.setattr(examples, "ROOT", tmp_path)
    monkeypatch.setattr(examples, "pages", lambda: [page])
    assert examples.unmarked_code() == ["page.md:1 ({code-block})"]


def test_blocks_that_cannot_run_as_marked_are_named(tmp_path, monkeypatch):
    page = _page(tmp_path, "<!-- test: a -->\n```python\nx = 1\n```\n<!-- test: a fast -->\n```bash\ntrue\n```\n"
                           "<!-- test: cfg -->\n```toml\nx = 1\n```\n<!-- test: b needs=wine -->\n```bash\ntrue\n```\n")
    monkeypatch.setattr(examples, "ROOT", tmp_path)
    monkeypatch.setattr(examples, "pages", lambda: [page])
    found = "\n".join(examples.problems())
    assert "the name is also used" in found and "unknown flags ['fast']" in found
    assert "a toml block needs writes=PATH" in found and "unknown need 'wine'" in found


def test_an_unclosed_block_is_an_error(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("text\n\n```python\nprint(1)\n")
    with pytest.raises(ValueError, match="page.md:3: unclosed code block"):
        _blocks_of(page, tmp_path)


def _blocks_of(page: Path, root: Path):
    saved = examples.ROOT
    examples.ROOT = root
    try:
        return examples.blocks(page)
    finally:
        examples.ROOT = saved


def test_a_failing_example_names_its_page_line_and_block(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("<!-- test: fine -->\n```python\nx = 41\n```\n\n<!-- test: broken -->\n```python\n"
                    "x += 1\nraise RuntimeError(f'x is {x}')\n```\n\n<!-- test: never -->\n```bash\ntouch ran\n```\n")
    todo = examples.runnable(_blocks_of(page, tmp_path))[0]
    with pytest.raises(AssertionError) as err:
        run_block(todo, tmp_path / "run")
    message = str(err.value)
    assert "broken" in message and 'page.md", line 9' in message      # the page's own line numbers
    assert "x is 42" in message                                        # one namespace: x from "fine"
    assert not (tmp_path / "run" / "ran").exists()                                 # nothing after the failure


def test_a_failing_shell_block_stops_the_page(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("<!-- test: sh -->\n```bash\nfalse | cat\necho after\n```\n")
    todo = examples.runnable(_blocks_of(page, tmp_path))[0]
    with pytest.raises(AssertionError, match="the shell block exited with 1"):
        run_block(todo, tmp_path / "run")
