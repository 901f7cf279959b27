"""The front doors' docstrings: their Examples run as doctests, and each has See Also,
Notes and References (STYLE.md, as scikit-image's watershed)."""

import doctest

import pytest

import volseg
from volseg.morse import MorseHierarchy, descending_complex

FRONT_DOORS = [volseg.segment_volume, descending_complex, MorseHierarchy]


@pytest.mark.parametrize("front_door", FRONT_DOORS, ids=lambda f: f.__name__)
def test_the_example_runs(front_door):
    finder = doctest.DocTestFinder(recurse=False)
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    tests = finder.find(front_door, front_door.__name__, globs={})
    assert tests and tests[0].examples, "no Example"
    for test in tests:
        runner.run(test)
    assert runner.summarize(verbose=False).failed == 0


@pytest.mark.parametrize("front_door", FRONT_DOORS, ids=lambda f: f.__name__)
def test_the_docstring_has_the_sections_of_a_reference(front_door):
    doc = front_door.__doc__
    for section in ("See Also", "Notes", "References", "Examples"):
        assert f"\n    {section}\n    {'-' * len(section)}" in doc, section
    assert "Edelsbrunner" in doc
