"""Make the figures the pages show, by running the examples that make them.

Run from anywhere: ``python docs/make_figures.py`` (about a minute); ``--slow`` also runs
the seed 000 sweep for its heat map (about a minute more on 2 cores). Each figure is the
output of a marked example of a page (the same examples the tests run, see
``docs/examples.py``), copied into ``docs/_static``:

=====================================  =========================  ==============================
``docs/_static/...``                   made by the page           file the example writes
=====================================  =========================  ==============================
``readme_estimate.png``                ``README.md``              ``estimate.png``
``tutorial_fading.png``                ``docs/tutorial.md``       ``tutorial_fading.png``
``filter_smoother_truth.png``          ``docs/guide/offline.md``  ``filter_smoother_truth.png``
``seed000_sweep_eta_over_true_ekf.png``   ``docs/guide/experiments``  ``out/sweep/heatmap_eta_over_true_ekf.png``
=====================================  =========================  ==============================
"""
from __future__ import annotations

import importlib.util
import shutil
import sys
import tempfile
from pathlib import Path

from fmu_models.infra.files import atomic_copy

HERE = Path(__file__).resolve().parent
_spec = importlib.util.spec_from_file_location("doc_examples", HERE / "examples.py")
examples = importlib.util.module_from_spec(_spec)
sys.modules["doc_examples"] = examples          # dataclasses look their module up there
_spec.loader.exec_module(examples)

#: figure in docs/_static -> (page, the example block that writes it, the file it writes)
FIGURES = {
    "readme_estimate.png": ("README.md", "readme-example", "estimate.png"),
    "tutorial_fading.png": ("docs/tutorial.md", "tutorial-compare", "tutorial_fading.png"),
    "filter_smoother_truth.png": ("docs/guide/offline.md", "offline", "filter_smoother_truth.png"),
    "seed000_sweep_eta_over_true_ekf.png": ("docs/guide/experiments.md", "experiments-sweep",
                                         "out/sweep/heatmap_eta_over_true_ekf.png"),
}


def make(slow: bool = False) -> list[Path]:
    """Run the pages' examples that make the figures (the slow ones only if ``slow``) and
    copy each figure into ``docs/_static``; returns the figures written."""
    written = []
    for figure, (page, name, produced) in FIGURES.items():
        page_blocks = examples.blocks(examples.ROOT / page)
        run = next(r for r in examples.runnable(page_blocks) if name in [b.name for b in r])
        run = run[:[b.name for b in run].index(name) + 1]       # up to the block that writes it
        if any(b.marker == "slow" for b in run) and not slow:
            print(f"skipped {figure} (made by a slow example: --slow)")
            continue
        folder = Path(tempfile.mkdtemp(prefix="doc-figure-"))
        try:
            examples.run(run, folder)
            target = atomic_copy(folder / produced, HERE / "_static" / figure)   # whole or not at all
            written.append(target)
            print(f"wrote {target.relative_to(examples.ROOT)}")
        finally:
            shutil.rmtree(folder, ignore_errors=True)
    return written


if __name__ == "__main__":
    make(slow="--slow" in sys.argv[1:])
