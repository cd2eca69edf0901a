"""Sweep recordings (``lcc_synth.recording.sweep``): every scenario's metrics per controller on
the ``scenario`` timeline and the summary table, read back from the file."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rerun")

from rerun.chunk import RrdReader  # noqa: E402

from lcc_synth import recording as R  # noqa: E402
from lcc_synth.errors import ConfigError  # noqa: E402
from lcc_synth.experiments.sweep import SWEEP_METRICS, aggregate  # noqa: E402


def recorded_samples(path: Path, name: str) -> dict[str, tuple[np.ndarray, np.ndarray, list]]:
    """``{metric: (scenario indices, values (scenarios, controllers), controller names)}`` of
    a sweep recording, from its chunks (the SeriesPoints names give the column order)."""
    prefix = f"/sweep/{R.entity_name(name)}/"
    rows: dict[str, list] = {}
    names: dict[str, list] = {}
    for ch in RrdReader(path).stream():
        entity = ch.entity_path
        if not entity.startswith(prefix) or entity.endswith("/report"):
            continue
        metric = entity[len(prefix):]
        rb = ch.to_record_batch()
        if ch.is_static:
            if "SeriesPoints:names" in rb.schema.names:
                names[metric] = rb.column("SeriesPoints:names").to_pylist()[-1]
            continue
        if "Scalars:scalars" in rb.schema.names:
            idx = rb.column("scenario").to_numpy()
            vals = rb.column("Scalars:scalars").to_pylist()
            rows.setdefault(metric, []).extend(zip(idx, vals, strict=True))
    out = {}
    for metric, pairs in rows.items():
        pairs.sort(key=lambda p: p[0])
        index = np.array([p[0] for p in pairs])
        values = np.array([[np.nan if v is None else v for v in p[1]] for p in pairs], float)
        out[metric] = (index, values, names[metric])
    return out


def _report(path: Path, name: str) -> str:
    entity = f"/sweep/{R.entity_name(name)}/report"
    for ch in RrdReader(path).stream():
        if ch.entity_path == entity:
            return ch.to_record_batch().column("TextDocument:text").to_pylist()[-1][-1]
    raise KeyError(entity)


@pytest.fixture()
def samples():
    rng = np.random.default_rng(3)
    out = {}
    for c in ("hdv", "mpc", "h 2"):
        out[c] = {k: rng.uniform(1.0, 9.0, 7) for k in SWEEP_METRICS}
        out[c]["aave"][2] = np.nan  # a collided run: no AAVE
        out[c].update(collisions=(np.arange(7) == 2).astype(float), aeb_activations=np.zeros(7),
                      jerk_1s_over_limit_s=np.zeros(7))  # fmt: skip
    return out


def test_every_sample_is_recorded_at_its_scenario_index(tmp_path, samples):
    labels = {"aave": "AAVE (m/s)", "min_spacing": "min spacing (m)",
              "max_abs_command": "max |u| (m/s²)", "collisions": "collisions"}  # fmt: skip
    summary = aggregate(samples, dict.fromkeys(samples, 0))
    path = R.record_sweep_file(tmp_path / "s.rrd", "my sweep", samples, labels, summary,
                               {"count": 7, "seed": 5})  # fmt: skip
    got = recorded_samples(path, "my sweep")
    assert set(got) == set(labels)
    for metric, (index, values, names) in got.items():
        assert names == ["hdv", "mpc", "h 2"]
        np.testing.assert_array_equal(index, np.arange(7))
        want = np.column_stack([samples[c][metric] for c in names])
        np.testing.assert_array_equal(values, want)  # NaN (the collided run) stays NaN
    report = _report(path, "my sweep")
    assert "7 scenarios x 3 controllers" in report
    m = summary["mpc"]["min_spacing"]
    row = next(line for line in report.splitlines() if line.startswith("| min spacing"))
    assert row.split(" | ")[2] == f"{R.core._fmt(m['mean'])} [{R.core._fmt(m['p5'])}, " \
        f"{R.core._fmt(m['p95'])}]"  # the mpc column: mean [p5, p95] of its samples
    assert "| max \\|u\\| (m/s²) |" in report  # the bar of |u| escaped: one cell
    assert row.count(" | ") == 3  # metric + 3 controllers
    assert "| collisions (scenarios) | 1 (1) | 1 (1) | 1 (1) |" in report
    assert "| seed | 5 |" in report


def test_bad_samples_are_refused_by_name(tmp_path, samples):
    with pytest.raises(ConfigError, match="at least one controller"):
        R.record_sweep_file(tmp_path / "a.rrd", "s", {}, {"aave": "AAVE"})
    with pytest.raises(ConfigError, match="has no samples of"):
        R.record_sweep_file(tmp_path / "b.rrd", "s", samples, {"no_such": "metric"})
    short = {**samples, "mpc": {**samples["mpc"], "aave": samples["mpc"]["aave"][:3]}}
    with pytest.raises(ConfigError, match="one value per scenario"):
        R.record_sweep_file(tmp_path / "c.rrd", "s", short, {"aave": "AAVE"})
    assert not list(tmp_path.iterdir())  # refused before any file is written


def test_the_report_ranks_a_controller_with_an_unsafe_scenario_after_the_safe_ones(tmp_path):
    """Safety before efficiency in the sweep's recording as in its table: ``fast`` has the
    better AAVE but one scenario under 2 m (unsafe), so its column comes after ``slow``'s,
    marked, its AAVE still shown; the count of unsafe scenarios is a row of its own."""
    n = 4
    base = {k: np.full(n, 5.0) for k in SWEEP_METRICS}
    base.update(collisions=np.zeros(n), aeb_activations=np.zeros(n),
                jerk_1s_over_limit_s=np.zeros(n), min_spacing=np.full(n, 9.0))  # fmt: skip
    samples = {"fast": {**base, "aave": np.full(n, 1.0),
                        "min_spacing": np.array([9.0, 1.5, 9.0, 9.0])},
               "slow": {**base, "aave": np.full(n, 3.0)}}  # fmt: skip
    summary = aggregate(samples, dict.fromkeys(samples, 0))
    assert summary["fast"]["unsafe_scenarios"] == 1 and summary["slow"]["unsafe_scenarios"] == 0
    path = R.record_sweep_file(tmp_path / "u.rrd", "u", samples, {"aave": "AAVE (m/s)"}, summary)
    lines = _report(path, "u").splitlines()
    table = [ln for ln in lines if ln.startswith("| ")]
    assert table[0] == "| metric | slow | fast |"
    assert table[1] == "| safety | safe | unsafe in 1/4 |"
    assert table[2].startswith("| AAVE (m/s) | 3 [3, 3] | 1 [1, 1] |")
    assert "| unsafe scenarios | 0 | 1 |" in table
