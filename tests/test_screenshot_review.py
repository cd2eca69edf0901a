"""``benchmarks/screenshot_review.py`` waits for the data, not for a fixed time: its settle
rule on sequences of captures (no browser is started here)."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def shot():
    spec = importlib.util.spec_from_file_location("screenshot_review",
                                                  ROOT / "benchmarks" / "screenshot_review.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    try:
        spec.loader.exec_module(module)
        yield module
    finally:
        sys.modules.pop(spec.name, None)


def test_settled_needs_identical_captures_far_larger_than_the_loading_page(shot):
    loading, view, other = b"L" * 100, b"V" * 400, b"W" * 400
    assert not shot._settled([loading, view, view], 3)  # too few captures yet
    assert shot._settled([loading, view, view, view], 3)
    assert not shot._settled([loading, view, view, other], 3)  # still drawing
    assert not shot._settled([loading] * 6, 3)  # still the loading page, however long
    assert not shot._settled([loading, b"V" * 299, b"V" * 299, b"V" * 299], 3)  # under 3x
