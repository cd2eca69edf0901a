"""The house style of every PNG writer: shared y-scales across controller rows, the CAV blue and
the head yellow (the Rerun recordings' colours), names as in the paper, units on the axes, and
legends outside every axes (bounding boxes in display coordinates), on small synthetic data."""

from __future__ import annotations

from types import SimpleNamespace

import matplotlib
import numpy as np
import pytest
from matplotlib.colors import to_rgb

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from lcc_synth import figures  # noqa: E402
from lcc_synth.recording.core import COLOR_CAV, COLOR_HEAD  # noqa: E402

CAV_BLUE = tuple(c / 255 for c in COLOR_CAV)
HEAD_YELLOW = tuple(c / 255 for c in COLOR_HEAD)


@pytest.fixture
def capture(monkeypatch):
    """Keep the figures the writers close, so that the test can inspect them."""
    plt.close("all")
    monkeypatch.setattr(plt, "close", lambda *a, **k: None)
    yield lambda: [plt.figure(n) for n in plt.get_fignums()]
    monkeypatch.undo()
    plt.close("all")


def _run(amplitude: float, m: int = 1, n: int = 2, collided: bool = False):
    """A fake SimResult: head, m HDVs ahead, CAV, n HDVs behind, sinusoids of ``amplitude``."""
    t = np.linspace(0.0, 60.0, 301)
    nv = m + n + 2
    lag = np.arange(nv)[None, :]
    vel = 15.0 + amplitude * np.sin(0.3 * (t[:, None] - lag))
    spacing = 20.0 + 2 * amplitude * np.cos(0.3 * (t[:, None] - lag))
    pos = -20.0 * lag + 15.0 * t[:, None]
    return SimpleNamespace(
        t=t, velocity=vel[None], spacing=spacing[None], position=pos[None], m=m, n=n,
        cav=m + 1, n_vehicles=nv, v_star=np.array([15.0]), s_star=np.array([20.0]),
        collided=np.array([[collided] * nv]),
    )  # fmt: skip


def _legends(fig):
    return [*fig.legends, *(ax.get_legend() for ax in fig.axes if ax.get_legend())]


def assert_legends_outside(fig):
    """Every legend box lies outside every (visible) axes box, so it covers no data."""
    fig.canvas.draw()
    r = fig.canvas.get_renderer()
    legs = _legends(fig)
    assert legs, "figure has no legend"
    for leg in legs:
        box = leg.get_window_extent(r)
        for ax in fig.axes:
            if ax.get_visible() and ax.axison:
                assert not box.overlaps(ax.get_window_extent(r)), (leg, ax)


def _line_colors(ax):
    return [to_rgb(line.get_color()) for line in ax.get_lines()]


def test_palette_is_the_recordings_and_controller_colours_avoid_cav_and_head():
    assert figures.PALETTE.cav == CAV_BLUE and figures.PALETTE.head == HEAD_YELLOW
    r, g, b = CAV_BLUE
    assert b > r and b > g  # blue
    for c in figures.PALETTE.controllers:
        assert np.abs(np.subtract(to_rgb(c), CAV_BLUE)).max() > 0.2
        assert np.abs(np.subtract(to_rgb(c), HEAD_YELLOW)).max() > 0.2
    cols = figures.controller_colors(["all_hdv", "paper", "h2", "mpc"])
    assert cols["all_hdv"] == figures.PALETTE.baseline and len(set(cols.values())) == 4


def test_display_names_read_as_in_the_paper():
    assert figures.display_name("case_a") == "Case A"
    assert figures.display_name("case_D") == "Case D"
    assert figures.display_name("fd_lcc") == "FD-LCC"
    assert figures.display_name("all_hdv") == "all HDVs"
    assert figures.display_name("my_gain") == "my_gain"


def test_profiles_rows_share_y_scales_cav_blue_head_yellow_units(tmp_path, capture):
    runs = {"all_hdv": _run(0.5), "h2": _run(4.0)}
    figures.plot_profiles(runs, tmp_path / "p.png", title="t")
    (fig,) = capture()
    axes = np.array(fig.axes).reshape(2, 2)
    for col in range(2):
        lims = {axes[row, col].get_ylim() for row in range(2)}
        assert len(lims) == 1  # shared
    lo, hi = axes[0, 0].get_ylim()
    assert lo < 15.0 - 4.0 and hi > 15.0 + 4.0  # the big run fits in the small run's row too
    for ax in axes[:, 0]:
        cols = _line_colors(ax)
        assert CAV_BLUE in cols and HEAD_YELLOW in cols
        assert "(m/s)" in ax.get_ylabel()
    assert "all HDVs" in axes[0, 0].get_ylabel() and "H2" in axes[1, 0].get_ylabel()
    assert "(m)" in axes[0, 1].get_ylabel() and "(s)" in axes[1, 0].get_xlabel()
    assert_legends_outside(fig)
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert labels == ["head vehicle", "HDV 1 (front)", "CAV (vehicle 2)", "HDV 4 (back)"]


@pytest.mark.parametrize("quantity", ["velocity", "spacing"])
def test_case_grid_titles_colours_shared_axes(tmp_path, capture, quantity):
    runs = {f"case_{c}": _run(a) for c, a in zip("abcd", (0.2, 0.4, 1.0, 3.0), strict=True)}
    figures.plot_case_grid(runs, tmp_path / "g.png", quantity)
    (fig,) = capture()
    assert [ax.get_title() for ax in fig.axes] == ["Case A", "Case B", "Case C", "Case D"]
    assert len({ax.get_ylim() for ax in fig.axes}) == 1
    for ax in fig.axes:
        cols = _line_colors(ax)
        assert CAV_BLUE in cols and (HEAD_YELLOW in cols) == (quantity == "velocity")
    unit = "(m/s)" if quantity == "velocity" else "(m)"
    assert unit in fig.axes[0].get_ylabel() and "(s)" in fig.axes[-1].get_xlabel()
    assert_legends_outside(fig)


def test_snapshots_share_y_and_mark_the_cav_blue(tmp_path, capture):
    figures.plot_snapshots(_run(1.0, m=0), _run(0.5, m=0), (10.0, 20.0), tmp_path / "s.png")
    (fig,) = capture()
    assert len({ax.get_ylim() for ax in fig.axes}) == 1
    for ax in fig.axes:
        colors = [tuple(to_rgb(c)) for col in ax.collections for c in col.get_facecolors()]
        assert CAV_BLUE in colors and HEAD_YELLOW in colors
    assert "(m/s)" in fig.axes[0].get_ylabel() and "(m)" in fig.axes[-1].get_xlabel()
    assert_legends_outside(fig)


def test_mpc_predictions_colours_and_legend(tmp_path, capture):
    res = _run(1.0, m=0, n=2)
    steps = np.arange(0.0, 60.0, 1.0)
    history = {
        "t": steps, "pred_time": np.linspace(0.0, 5.0, 11),
        "predicted_velocity": np.full((1, steps.size, 11, 3), 15.0),
        "predicted_spacing": np.full((1, steps.size, 11, 3), 20.0),
    }  # fmt: skip
    figures.plot_mpc_predictions(res, history, tmp_path / "m.png", window=(10.0, 50.0))
    (fig,) = capture()
    assert CAV_BLUE in _line_colors(fig.axes[0]) and HEAD_YELLOW in _line_colors(fig.axes[0])
    assert "(m/s)" in fig.axes[0].get_ylabel() and "(m)" in fig.axes[1].get_ylabel()
    assert_legends_outside(fig)


def test_gamma_curves_units_names_and_legend(tmp_path, capture):
    omega = np.logspace(-2, 1, 50)
    rep = SimpleNamespace(verdict="string_stable", gamma_peak=1.0)
    curves = {name: (1 / (1 + omega**2), rep) for name in
              ("all_hdv", "case_a", "h2", "h2 @ 0.1 s latency")}  # fmt: skip
    figures.plot_gamma_curves(curves, omega, tmp_path / "g.png")
    (fig,) = capture()
    (ax,) = fig.axes
    assert "(rad/s)" in ax.get_xlabel() and "m/s per m/s" in ax.get_ylabel()
    texts = [t.get_text() for t in fig.legends[0].get_texts()]
    assert texts[0].startswith("all HDVs:") and texts[1].startswith("Case A:")
    lines = ax.get_lines()
    assert lines[2].get_color() == lines[3].get_color() and lines[3].get_linestyle() == ":"
    assert_legends_outside(fig)


def test_control_energy_and_pareto_and_region_legends_outside(tmp_path, capture):
    from lcc_synth.analysis.energy import energy_vs_size
    from lcc_synth.models.hdv import OVM

    coef = OVM(alpha=0.6, beta=0.9, v_max=30.0, s_st=5.0, s_go=35.0).linear_coefficients(15.0)
    dbl = energy_vs_size(coef, horizons=(10.0, 30.0), n_max=6)
    mpw = energy_vs_size(coef, horizons=(10.0, 30.0), n_max=6, method="mp")
    figures.plot_control_energy(mpw, tmp_path / "e.png", reference=dbl)
    pareto = [{"count": c, "h2": 2.0 - 0.1 * c, "on_front": True, "vehicles": list(range(c))}
              for c in range(4)]  # fmt: skip
    figures.plot_pareto_front(pareto, 1.5, tmp_path / "f.png")
    mu = k = np.linspace(-1.0, 1.0, 5)
    labels = np.array([[0, 1, 2, 2, 1]] * 5, dtype=np.int8)
    rm = SimpleNamespace(mu=mu, k=k, labels=labels, vehicle=1, fixed={},
                         string_stable_fraction=0.4)  # fmt: skip
    figures.plot_region_maps({"a": rm}, tmp_path / "r.png")
    fig_e, fig_f, fig_r = capture()
    texts = [t.get_text() for t in fig_e.legends[0].get_texts()]
    assert any("multiprecision" in s for s in texts) and any("singular from n = 5" in s
                                                             for s in texts)  # fmt: skip
    # the multiprecision lines go to n = 6; float64 stops before
    assert max(max(line.get_xdata()) for line in fig_e.axes[0].get_lines()) == 6
    assert "(1/s²)" in fig_r.axes[0].get_xlabel() and "(1/s)" in fig_r.axes[0].get_ylabel()
    for fig in (fig_e, fig_f, fig_r):
        assert_legends_outside(fig)


def test_the_legend_check_can_fail(tmp_path, capture):
    """A legend drawn inside the axes is caught (the check is not vacuous)."""
    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1], label="x")
    ax.legend(loc="upper left")
    with pytest.raises(AssertionError):
        assert_legends_outside(fig)


# ------------------------------------------------- vehicles told apart, AEB, measured points


def _distance(a, b) -> float:
    return float(np.abs(np.subtract(to_rgb(a), to_rgb(b))).max())


@pytest.mark.parametrize(("n_vehicles", "cavs", "ring"),
                         [(12, [1], False), (9, [3, 6], False), (5, [2], False),
                          (20, [0], True), (40, [0, 10, 20, 30], True)])  # fmt: skip
def test_vehicle_styles_tell_every_vehicle_apart(n_vehicles, cavs, ring):
    styles = figures.vehicle_styles(n_vehicles, cavs, ring)
    assert len(styles) == n_vehicles
    assert styles == figures.vehicle_styles(n_vehicles, cavs, ring)  # a pure function
    colors = [st["color"] for st in styles]
    for i in range(n_vehicles):  # every pair of vehicles differs in colour
        for j in range(i):
            assert _distance(colors[i], colors[j]) > 0.01, (i, j)
    hdvs = [j for j in range(n_vehicles) if j not in cavs and (ring or j > 0)]
    for j in hdvs:  # the HDVs' colormap stays away from the head's yellow and every CAV colour
        assert "marker" not in styles[j]
        assert _distance(colors[j], HEAD_YELLOW) > 0.1
        for c in cavs:
            assert _distance(colors[j], colors[c]) > 0.1
    # sequential: the HDVs' colours move monotonically along the colormap (front to back)
    from matplotlib import colormaps

    name, lo, hi = figures.style.HDV_COLORMAP
    ref = [to_rgb(colormaps[name](lo + (hi - lo) * i / max(len(hdvs) - 1, 1))) for i in
           range(len(hdvs))]  # fmt: skip
    np.testing.assert_allclose([to_rgb(colors[j]) for j in hdvs], ref, rtol=0, atol=1e-12)
    markers = [styles[c]["marker"] for c in cavs]
    assert len(set(markers)) == len(cavs)  # each CAV its own marker
    assert len({tuple(to_rgb(colors[c])) for c in cavs}) == len(cavs)  # and colour
    assert to_rgb(colors[cavs[0]]) == CAV_BLUE
    if not ring:
        assert to_rgb(colors[0]) == HEAD_YELLOW and styles[0]["label"] == "head vehicle"


def test_aeb_intervals_are_the_runs_of_the_flags():
    t = np.arange(10) * 0.5
    flags = np.array([0, 1, 1, 0, 0, 1, 0, 0, 1, 1], dtype=bool)
    # independent truth: each run [first, last] of True, ending at the next sample's time
    assert figures.aeb_intervals(t, flags) == [(0.5, 1.5), (2.5, 3.0), (4.0, 4.5)]
    assert figures.aeb_intervals(t, np.zeros(10, bool)) == []
    assert figures.aeb_intervals(t, np.ones(10, bool)) == [(0.0, 4.5)]


def test_profiles_shade_the_recorded_aeb_intervals_per_cav(tmp_path, capture):
    from matplotlib.colors import to_rgba
    from matplotlib.patches import Rectangle

    res = _run(1.0, m=1, n=3)
    cavs = (2, 4)
    res.cavs = cavs
    aeb = np.zeros((1, res.t.size, 2), dtype=bool)
    aeb[0, 40:61, 0] = True  # CAV at column 2: t = 8.0 .. 12.0 s (samples every 0.2 s)
    aeb[0, 100:106, 1] = True  # CAV at column 4: t = 20.0 .. 21.0 s
    aeb[0, 200:211, 1] = True  # and t = 40.0 .. 42.0 s
    res.aeb_active = aeb
    figures.plot_profiles({"mpc": res, "h2": _run(0.5, m=1, n=3)}, tmp_path / "p.png")
    (fig,) = capture()
    axes = np.array(fig.axes).reshape(2, 2)
    styles = figures.vehicle_styles(res.n_vehicles, cavs)
    want = {(8.0, 12.2, to_rgb(styles[2]["color"])), (20.0, 21.2, to_rgb(styles[4]["color"])),
            (40.0, 42.2, to_rgb(styles[4]["color"]))}  # fmt: skip
    for ax in axes[0]:
        got = set()
        for p in ax.patches:
            if isinstance(p, Rectangle) or hasattr(p, "get_xy"):
                xy = np.asarray(p.get_xy()) if not isinstance(p, Rectangle) else None
                x0, x1 = ((p.get_x(), p.get_x() + p.get_width()) if xy is None
                          else (xy[:, 0].min(), xy[:, 0].max()))  # fmt: skip
                got.add((round(x0, 6), round(x1, 6), to_rgb(to_rgba(p.get_facecolor()))))
        assert got == {(round(a, 6), round(b, 6), c) for a, b, c in want}
    assert not axes[1, 0].patches and not axes[1, 1].patches  # no AEB in the other run
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert labels.count("AEB active") == 1 and "CAV (vehicle 4)" in labels
    assert_legends_outside(fig)


def test_gamma_measured_points_are_points_and_the_axis_ends_where_curves_decay(tmp_path,
                                                                                capture):
    omega = np.logspace(-3, 1.5, 400)
    stable = SimpleNamespace(verdict="string_stable", gamma_peak=1.0)
    lin = 1.0 / np.sqrt(1.0 + (omega / 0.5) ** 8)  # below 1e-3 above 0.5 * 1000**0.25 = 2.81
    measured = {
        name: (np.full(omega.shape, np.nan),
               SimpleNamespace(omega=np.array([0.05, 0.1, 0.3, 1.0]), ratio=r,
                               gamma_peak=float(r.max())))
        for name, r in (("mpc_delay @ 0.1 s latency", np.array([1.01, 1.03, 1.14, 0.19])),
                        ("deep_lcc @ 0.1 s latency", np.array([1.02, 1.04, 1.13, 0.19])))
    }  # fmt: skip
    curves = {"h2": (lin, stable), **measured}
    figures.plot_gamma_curves(curves, omega, tmp_path / "g.png")
    (fig,) = capture()
    (ax,) = fig.axes
    lines = [ln for ln in ax.get_lines() if len(ln.get_xdata()) > 2]
    points = [ln for ln in lines if ln.get_linestyle() == "None"]
    assert len(points) == 2  # the measured ratios: markers only, no line between them
    assert points[0].get_marker() != points[1].get_marker()  # mpc_delay not hidden
    lo, hi = ax.get_xlim()
    w_decay = 0.5 * 1000**0.25
    assert w_decay <= hi <= 1.5 * w_decay * 1.05 and hi < omega[-1]
    # from a third of where the first curve leaves 1 by 1e-3: 0.5 * (2e-3)**(1/8) = 0.230
    # (|Γ| = 1 - x^8 / 2 near 0), the measured points start at 0.05
    assert lo == pytest.approx(0.05 / 3, rel=0.02)
    assert ax.get_ylim()[1] == pytest.approx(1.06 * 1.14)
    assert_legends_outside(fig)
    fig.canvas.draw()  # the legend takes at most a third of the figure's height
    box = fig.legends[0].get_window_extent(fig.canvas.get_renderer())
    assert box.height < fig.bbox.height / 3


def _pixels(path):
    from PIL import Image

    return np.asarray(Image.open(path).convert("RGBA"))


def test_a_png_is_drawn_once_and_as_savefig_lays_it_out(tmp_path, capture, monkeypatch):
    """A PNG is laid out once and drawn once (savefig alone draws a layout-only pass first),
    and its pixels are those of matplotlib's own constrained-layout ``savefig`` of the same
    figure; the figure keeps its layout engine."""
    from matplotlib.figure import Figure

    draws = []
    draw = Figure.draw
    monkeypatch.setattr(Figure, "draw", lambda self, r: (draws.append(1), draw(self, r))[1])
    res = _run(1.0, m=1, n=3)
    res.aeb_active = np.zeros((1, res.t.size), dtype=bool)
    res.aeb_active[0, 40:61] = True
    figures.plot_profiles({"mpc": res, "h2": _run(3.0)}, tmp_path / "p.png", title="t")
    assert len(draws) == 1
    (fig,) = capture()
    assert fig.get_layout_engine() is not None and fig.get_constrained_layout()
    fig.savefig(tmp_path / "ref.png", dpi=110)  # matplotlib's two passes
    assert len(draws) == 3
    np.testing.assert_array_equal(_pixels(tmp_path / "p.png"), _pixels(tmp_path / "ref.png"))


@pytest.mark.parametrize("ext", [".pdf", ".svg"])
def test_vector_files_are_laid_out_by_savefig(tmp_path, capture, ext):
    """A vector file (text measured at 72 dpi by its own renderer) keeps ``savefig``'s own
    layout: the axes sit where matplotlib's ``savefig`` to that type puts them, which is not
    where a PNG's are (to a few thousandths of the figure)."""
    runs = {"mpc": _run(1.0), "h2": _run(3.0)}
    figures.plot_profiles(runs, tmp_path / f"p{ext}")
    figures.plot_profiles(runs, tmp_path / "p.png")
    vec, png = capture()
    head = (tmp_path / f"p{ext}").read_bytes()[:100]
    assert head.startswith(b"%PDF") if ext == ".pdf" else b"<svg" in head or b"<?xml" in head
    got = [ax.get_position().bounds for ax in vec.axes]
    vec.savefig(tmp_path / f"ref{ext}")
    np.testing.assert_allclose(got, [ax.get_position().bounds for ax in vec.axes], atol=1e-12)
    assert not np.allclose(got, [ax.get_position().bounds for ax in png.axes], atol=1e-4)
