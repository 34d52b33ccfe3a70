"""Sphinx configuration of the pendulum-cosim documentation.

Build it with ``python -m sphinx -b html docs docs/_build`` (then open
``docs/_build/index.html``). The pages are MyST Markdown; the API reference is generated
from the docstrings by autosummary. The build is nitpicky: every cross-reference must
resolve, and ``tests/test_docs.py`` builds with ``-W --keep-going -n`` (warnings are errors).
"""
from __future__ import annotations

import importlib
import inspect
import sys
import typing
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))          # the checkout's packages, also when not installed

project = "pendulum-cosim"
author = "pendulum-cosim authors"
copyright = "pendulum-cosim authors"
try:
    from importlib.metadata import version as _version

    release = _version("pendulum-cosim")
except Exception:                      # noqa: BLE001 - a checkout without an install has no metadata
    release = ""

extensions = ["myst_parser", "sphinx.ext.autodoc", "sphinx.ext.autosummary", "sphinx.ext.napoleon",
              "sphinx.ext.viewcode", "sphinx.ext.mathjax"]
source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "index"
exclude_patterns = ["_build", "README.md", "examples.py", "make_figures.py"]
templates_path = ["_templates"]
html_static_path = ["_static"]
html_theme = "alabaster"
html_theme_options = {"description": "FMI co-simulation components for state estimation on two pendulums",
                      "fixed_sidebar": True}
html_sidebars = {"**": ["about.html", "navigation.html", "searchbox.html"]}

# MyST: $...$ and $$...$$ math, ::: fences, header anchors for links like page.md#section
myst_enable_extensions = ["dollarmath", "colon_fence", "deflist"]
myst_heading_anchors = 3

nitpicky = True
# Names of other projects: no inventory of theirs is available to an offline, hermetic
# build (no intersphinx downloads), so a reference to them cannot resolve; each is listed.
nitpick_ignore = [
    ("py:class", "abc.ABC"),        # the standard library's: a base class shown by show-inheritance
    ("py:class", "ctypes.Structure"),  # likewise (the native kernel's structures)
]

# the API reference
autosummary_generate = True
autosummary_imported_members = False
autodoc_default_options = {"members": True, "show-inheritance": True, "ignore-module-all": True}
autodoc_member_order = "bysource"
autodoc_typehints = "none"         # the numpy-style docstrings carry types with shapes and units
napoleon_google_docstring = False
napoleon_numpy_docstring = True
napoleon_use_rtype = False
# Types in numpy-style docstrings are prose ("ndarray, shape (nx,)", "float [s]"): render
# them as text, as numpydoc does, rather than as one cross-reference per word.
napoleon_use_param = False
napoleon_custom_sections = [("Attributes", "params_style")]
# One short name of two objects (Q and R of a filter and of a run) is not an error.
suppress_warnings = ["autosummary.import_cycle", "ref.python"]


def _lookup(dotted: str, context=None):
    """The object ``dotted`` names in ``context``'s namespace (a module or class), or as an
    import path if ``context`` is None; None if it names nothing."""
    parts = dotted.split(".")
    if context is not None:
        obj, rest = context, parts
    else:
        for i in range(len(parts), 0, -1):
            try:
                obj, rest = importlib.import_module(".".join(parts[:i])), parts[i:]
                break
            except ImportError:
                continue
        else:
            return None
    for part in rest:
        if not hasattr(obj, part):
            return None
        obj = getattr(obj, part)
    return obj


def _documented(domain, obj, parent, attr: str) -> str | None:
    """The name under which ``obj``, reached as ``parent.attr``, is documented, or None."""
    if inspect.ismodule(obj):
        name = obj.__name__
        return name if name in domain.modules else None
    if inspect.isclass(parent):        # a member: documented on the class that defines it
        owner = next((k for k in parent.__mro__ if attr in vars(k)), parent)
        name = f"{owner.__module__}.{owner.__qualname__}.{attr}"
    elif inspect.isclass(obj) or inspect.isfunction(obj):
        name = f"{obj.__module__}.{obj.__qualname__}"
    else:                              # data: the documented name that holds this very object
        name = next((n for n in domain.objects if n.rsplit(".", 1)[-1] == attr and _lookup(n) is obj), None)
    return name if name in domain.objects else None


def resolve_by_python(app, env, node, contnode):
    """Resolve a reference the way Python resolves the name: as an import path
    (``estimators.EKF`` is :class:`estimators.ekf.EKF`, documented where it is defined), or as
    the module (and class) in whose docstring it is written sees it (its imports). Only a
    documented object is a target; anything else stays a warning."""
    if node.get("refdomain") != "py":
        return None
    from sphinx.util.nodes import make_refnode

    domain = env.domains["py"]
    target = node["reftarget"].lstrip("~.").removesuffix("()")
    module = sys.modules.get(node.get("py:module") or "")
    contexts = [None]
    if module is not None:
        cls = _lookup(node["py:class"], module) if node.get("py:class") else None
        contexts = [c for c in (cls, module) if c is not None] + [None]
    head, _, attr = target.rpartition(".")
    for context in contexts:
        obj = _lookup(target, context)
        if obj is None:
            continue
        parent = _lookup(head, context) if head else context
        name = _documented(domain, obj, parent, attr)
        if name is not None:
            entry = domain.objects.get(name) or domain.modules[name]
            return make_refnode(app.builder, node["refdoc"], entry.docname, entry.node_id, contnode, name)
    return None


def public_bases(app, name, obj, options, bases):
    """Show a class's public ancestry: a private base of this project is replaced by its own
    bases, and ``Generic[T]`` (typing's machinery, not a base a user derives from) is left out."""
    i = 0
    while i < len(bases):
        base = bases[i]
        if getattr(base, "__origin__", None) is typing.Generic:
            del bases[i]
        elif getattr(base, "__name__", "").startswith("_") and \
                getattr(base, "__module__", "").split(".")[0] in ("fmu_models", "estimators", "cosim"):
            bases[i:i + 1] = [b for b in base.__bases__ if b is not object]
        else:
            i += 1


def setup(app):
    app.connect("missing-reference", resolve_by_python)
    app.connect("autodoc-process-bases", public_bases)
