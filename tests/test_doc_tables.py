"""The tables of measured figures on the pages and in the README are what the benchmark
scripts wrote (``bench/doc_tables.py``): every table block is its script's table made from
the figures the script's last run saved in ``bench/figures/``, and every table a script
defines is on a page. Speed cannot be measured again here; the Reference FMUs' verdicts
(accuracy) are: the slow test runs every case again and compares with the saved figures."""
import importlib.util
import json
import sys
from pathlib import Path

import pytest
from testkit import reference_cases as rc

ROOT = Path(__file__).parents[1]
_spec = importlib.util.spec_from_file_location("doc_tables", ROOT / "bench" / "doc_tables.py")
doc_tables = importlib.util.module_from_spec(_spec)
sys.modules["doc_tables"] = doc_tables
_spec.loader.exec_module(doc_tables)

BLOCKS = [b for page in doc_tables.pages() for b in doc_tables.blocks(page)]


def test_the_pages_have_table_blocks():
    scripts = {b.script for b in BLOCKS}
    assert {"bench/bench_reference_fmus.py", "bench/bench_master.py", "bench/doc_tables.py"} <= scripts, scripts


@pytest.mark.parametrize("block", BLOCKS, ids=lambda b: f"{b.page.relative_to(ROOT)}:{b.script}:{b.name}")
def test_a_table_block_is_what_its_script_made_of_its_saved_figures(block):
    expected = doc_tables.render(block, doc_tables.Saved())
    assert block.body == expected, (f"{block.page.relative_to(ROOT)}: the table {block.name!r} of {block.script} is "
                                    f"not what the script's saved figures make; run python {block.script} "
                                    f"--write-docs\n--- page\n{block.body}--- script\n{expected}")


def test_every_table_of_a_script_is_on_a_page():
    shown = {(b.script, b.name) for b in BLOCKS}
    writers = [f"bench/{p.name}" for p in sorted((ROOT / "bench").glob("*.py")) if "\nTABLES = " in p.read_text()]
    assert len(writers) >= 9, writers
    missing = [(script, name) for script in writers for name in doc_tables.tables_of(script)
               if (script, name) not in shown]
    assert not missing, f"tables no page shows: {missing}"


def test_every_saved_figures_file_says_when_and_where_it_was_measured():
    for path in sorted(doc_tables.FIGURES.glob("*.json")):
        saved = json.loads(path.read_text())
        assert set(saved) == {"run", "figures"}, path
        assert {"date", "commit", "cores", "cpu", "python", "versions"} <= set(saved["run"]), path
        assert (ROOT / "bench" / f"{path.stem}.py").exists(), f"{path.name}: no script bench/{path.stem}.py"


def test_a_malformed_block_is_an_error(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("text\n<!-- table: bench/bench_fmu.py fmu -->\n| a |\n|---|\n\nmore\n")
    with pytest.raises(ValueError, match="1 table markers but 0 well-formed blocks"):
        doc_tables.blocks(page)


def test_writing_the_docs_replaces_only_the_blocks(tmp_path, monkeypatch):
    """``write_docs`` saves the figures with the run's description and rewrites each block
    from them, leaving the text around it as it was."""
    (tmp_path / "bench" / "figures").mkdir(parents=True)
    script = tmp_path / "bench" / "bench_toy.py"
    script.write_text("TABLES = {'toy': lambda saved: f\"| x |\\n|---|\\n| {saved['bench_toy']['figures']['x']} |\"}\n")
    page = tmp_path / "README.md"
    page.write_text("before\n<!-- table: bench/bench_toy.py toy -->\nold\n<!-- /table -->\nafter\n")
    (tmp_path / "docs").mkdir()
    monkeypatch.setattr(doc_tables, "ROOT", tmp_path)
    monkeypatch.setattr(doc_tables, "FIGURES", tmp_path / "bench" / "figures")
    doc_tables.tables_of.cache_clear()
    try:
        assert doc_tables.write_docs(str(script), {"x": 42}) == [page]
    finally:
        doc_tables.tables_of.cache_clear()
    assert page.read_text() == ("before\n<!-- table: bench/bench_toy.py toy -->\n| x |\n|---|\n| 42 |\n"
                                "<!-- /table -->\nafter\n")
    saved = json.loads((tmp_path / "bench" / "figures" / "bench_toy.json").read_text())
    assert saved["figures"] == {"x": 42} and saved["run"]["cores"] >= 1


@pytest.mark.slow
@pytest.mark.skipif(rc.reference_dir() is None, reason="the Reference FMUs are absent: PENDULUM_COSIM_REFERENCE_FMUS "
                                                       "names their folder")
def test_the_reference_fmu_verdicts_are_a_fresh_run():
    """The third-party page's table of the Reference FMUs is accuracy, not speed: run every
    case again (from Python) and compare the verdicts with those the script saved."""
    sys.path.append(str(ROOT / "bench"))
    script = doc_tables.tables_of("bench/bench_reference_fmus.py")["reference"].__globals__
    saved = doc_tables.Saved()["bench_reference_fmus"]["figures"]["verdicts"]
    assert script["reference_figures"](cli=False)["verdicts"] == saved
