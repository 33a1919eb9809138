"""The names a notebook imports from ``semlab`` exist, and the contracts keep their signatures."""

import inspect

import pytest

import semlab


@pytest.mark.parametrize("name", semlab.__all__)
def test_every_public_name_resolves(name):
    assert getattr(semlab, name) is not None


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
