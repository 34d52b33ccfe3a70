"""The API reference builds from the docstrings with no warning, and lists every public name."""
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from testkit.docstrings import public_objects

ROOT = Path(__file__).parents[1]
pytestmark = pytest.mark.docs


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    pytest.importorskip("sphinx", reason="the API reference needs Sphinx (in the dev extra)")
    src = tmp_path_factory.mktemp("docs") / "docs"
    shutil.copytree(ROOT / "docs", src, ignore=shutil.ignore_patterns("_build", "generated"))
    out = src / "_build"
    proc = subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html", str(src),
                           str(out)], capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return out


def test_the_reference_builds_without_warnings(built):
    assert (built / "index.html").exists()


def test_every_public_name_is_in_the_reference(built):
    from sphinx.util.inventory import InventoryFile

    with open(built / "objects.inv", "rb") as f:
        inv = InventoryFile.load(f, "", lambda base, uri: uri)
    documented = {name for kind in inv.values() for name in kind} if isinstance(inv, dict) else \
        {item.name for item in inv}
    missing = [q for q, _ in public_objects(private_modules=False) if q not in documented]
    assert not missing, f"not in the API reference: {missing}"
