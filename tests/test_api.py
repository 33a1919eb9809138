"""The names a notebook imports from ``semlab`` exist, and the contracts keep their signatures."""

import importlib
import inspect

import pytest

import semlab

PUBLIC = [n for n in semlab.__all__ if n != "__version__"]


@pytest.mark.parametrize("name", PUBLIC)
def test_every_public_name_resolves_to_its_module_object(name):
    # The lazy table must hand out the very object its module defines (not a stale copy, not a
    # same-named object from elsewhere), and that object must be documented for the notebooks.
    module = importlib.import_module(semlab._EXPORTS[name])
    obj = getattr(semlab, name)
    assert obj is getattr(module, name)
    assert inspect.isclass(obj) or inspect.isfunction(obj)
    defined_in = inspect.getmodule(obj).__name__
    assert defined_in == module.__name__ or defined_in.startswith(module.__name__ + "."), (
        f"{name} comes from {defined_in}, the export table says {module.__name__}")
    assert (inspect.getdoc(obj) or "").strip(), f"{name} has no docstring"
    assert name in dir(semlab)


def test_version_is_the_package_metadata():
    from importlib.metadata import version

    assert semlab.__version__ == version("semlab")


def test_unknown_names_raise_attribute_error():
    with pytest.raises(AttributeError):
        semlab.no_such_thing  # noqa: B018


@pytest.mark.parametrize("func, positional, keyword", [
    ("track", ["frames", "roi"], ["method"]),
    ("characterise_hysteresis", ["microscope", "axis", "roi"], ["u_min", "u_max"]),
    ("fit_hysteresis", ["characterisation", "kind"], []),
    ("step_response", ["microscope", "axis", "roi", "step_px"], ["model", "feedforward", "n_frames"]),
])
def test_contract_signatures(func, positional, keyword):
    params = inspect.signature(getattr(semlab, func)).parameters
    names = list(params)
    assert names[:len(positional)] == positional
    for k in keyword:
        assert params[k].kind is inspect.Parameter.KEYWORD_ONLY, f"{func}: {k} must be keyword-only"
