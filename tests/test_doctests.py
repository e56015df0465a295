"""The ``>>>`` examples of the public API (the modules behind ``fovexp.__all__``) run and give
what they show. Run as doctests of a fixed list of modules, so that collecting them imports
nothing of PsychoPy, the tracker SDK or the GPU backend."""

import doctest
import importlib

import pytest

#: The modules of the public names (fovexp/__init__.py) whose docstrings carry examples.
MODULES = ("params", "geometry", "io", "pipeline", "backends", "resources", "errors",
           "sequence")


@pytest.mark.parametrize("name", MODULES)
def test_examples(name, monkeypatch, tmp_path):
    monkeypatch.chdir(tmp_path)  # protocols and displays found as shipped, not in a cwd
    module = importlib.import_module(f"fovexp.{name}")
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE,
                             verbose=False)
    assert result.attempted > 0, f"fovexp.{name} has no examples"
    assert result.failed == 0
