"""Sphinx configuration of the API reference (``python -m sphinx -W -b html docs docs/_build``;
the test ``tests/test_docs.py`` builds it with warnings as errors)."""
project = "pendulum-cosim"
author = "pendulum-cosim"
extensions = ["sphinx.ext.autodoc", "sphinx.ext.autosummary", "sphinx.ext.napoleon", "sphinx.ext.viewcode"]
autosummary_generate = True
autosummary_imported_members = False
autodoc_default_options = {"members": True, "show-inheritance": True, "ignore-module-all": True}
autodoc_member_order = "bysource"
autodoc_typehints = "none"
autodoc_mock_imports = []
napoleon_google_docstring = False
napoleon_numpy_docstring = True
napoleon_use_ivar = True
napoleon_use_rtype = False
templates_path = ["_templates"]
exclude_patterns = ["_build"]
html_theme = "alabaster"
# ambiguous short cross-references (Q, R of a filter and of a batch) resolve to either; not an error
suppress_warnings = ["autosummary.import_cycle", "ref.python"]
