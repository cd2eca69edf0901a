"""Test-session set-up: DeeP-LCC's data cache stays out of the repository.

Problem files name the cache relative to the working directory (``results/deeplcc`` by
default); during the tests a cache directory that would land inside the repository is
redirected into one temporary directory of the session (a test that changes to its own
directory, or names an absolute one, is left alone). The data are still cached and reused
within the session.
"""

from __future__ import annotations

import functools
from dataclasses import replace
from pathlib import Path

import pytest


@pytest.fixture(scope="session", autouse=True)
def _deeplcc_cache_outside_the_repository(tmp_path_factory):
    import lcc_synth.deeplcc.build as build
    import lcc_synth.deeplcc.data as data

    root = tmp_path_factory.mktemp("deeplcc_cache")
    repo = Path(__file__).resolve().parents[1]
    original = data.load_or_collect

    @functools.wraps(original)  # the package's docstring checks see the real function's
    def load_or_collect(base, settings):
        where = (Path.cwd() / settings.cache_dir).resolve()
        if where.is_relative_to(repo):
            settings = replace(settings, cache_dir=str(root / where.relative_to(repo)))
        return original(base, settings)

    mp = pytest.MonkeyPatch()
    mp.setattr(data, "load_or_collect", load_or_collect)
    mp.setattr(build, "load_or_collect", load_or_collect)
    yield root
    mp.undo()
