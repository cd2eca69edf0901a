"""Test-session set-up: the ``sumo`` marker, and DeeP-LCC's data cache kept out of the
repository.

**SUMO.** A test marked ``@pytest.mark.sumo`` needs libsumo (the ``sumo`` extra): it is
skipped when libsumo is not importable, except in CI (``CI=true``), where it runs and a
missing SUMO fails (:func:`have_sumo`, checked by ``tests/test_sumo.py``).

**DeeP-LCC's data cache.**
Problem files name the cache relative to the working directory (``results/deeplcc`` by
default); during the tests a cache directory that would land inside the repository is
redirected into one temporary directory of the session (a test that changes to its own
directory, or names an absolute one, is left alone). The data are still cached and reused
within the session.
"""

from __future__ import annotations

import contextlib
import functools
import io
import os
from dataclasses import replace
from pathlib import Path

import pytest

IN_CI = os.environ.get("CI", "").lower() == "true"


def have_sumo() -> bool:
    """Is libsumo importable? (Its import prints a banner: silenced.)"""
    try:
        with contextlib.redirect_stdout(io.StringIO()):
            import libsumo  # noqa: F401
    except ImportError:
        return False
    return True


def pytest_configure(config):
    config.addinivalue_line("markers", 'sumo: needs libsumo (pip install -e ".[sumo]"); '
                            "skipped without it, except in CI")  # fmt: skip


def pytest_collection_modifyitems(config, items):
    if IN_CI or have_sumo():
        return
    skip = pytest.mark.skip(reason='SUMO not installed (pip install -e ".[sumo]")')
    for item in items:
        if "sumo" in item.keywords:
            item.add_marker(skip)


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
