"""Figures of simulation runs: profiles, case grids (Figs. 10, 12), snapshots (Fig. 11), MPC
predictions, Table II bars and sweep distributions (house style: :mod:`.style`)."""

from __future__ import annotations

from pathlib import Path

from lcc_synth.figures.style import (
    PALETTE,
    _legend_below,
    _pyplot,
    _save,
    _styled,
    aeb_intervals,
    controller_colors,
    display_name,
    vehicle_style,
    vehicle_styles,
)


@_styled
def plot_profiles(results, path: str | Path, title: str | None = None, run: int = 0) -> Path:
    """Velocity and spacing of every vehicle over time, one row per controller.

    Parameters
    ----------
    results : mapping of str to lcc_synth.simulation.results.SimResult
        ``{controller: result}`` of one scenario (same layout for all).
    path : str or Path
        Output file; its extension picks the type (``.png``, ``.pdf``, ``.svg``).
    title : str, optional
    run : int
        Batch member to draw.

    Every vehicle can be told apart (:func:`vehicle_styles`): head yellow, each CAV its own
    colour and marker (drawn on top), the HDVs a sequential colormap from front to back
    (dashed ahead of the first CAV; a ring: no head, every vehicle's spacing). The intervals
    in which a CAV's emergency braking (AEB) was active (the result's ``aeb_active``) are
    shaded in that CAV's colour (:func:`aeb_intervals`). The rows share their y-axes
    (velocity, spacing) so that controllers compare by eye; the legend sits under them.
    """
    import numpy as np

    plt = _pyplot()
    path = Path(path)
    items = list(results.items())
    fig, axes = plt.subplots(
        len(items), 2, figsize=(11, 2.3 * len(items) + 1.0), sharex=True, sharey="col",
        squeeze=False, constrained_layout=True,
    )  # fmt: skip
    aeb_label = True
    for row, (name, res) in enumerate(items):
        ring = bool(getattr(res, "ring", False))
        cavs = getattr(res, "cavs", None)
        cavs = [res.cav] if cavs is None else [int(c) for c in cavs]
        styles = vehicle_styles(res.n_vehicles, cavs, ring)
        every = max(1, res.t.size // 12)  # a CAV's marker about 12 times per curve
        for j in range(res.n_vehicles):
            kw = {**styles[j], "markevery": every} if "marker" in styles[j] else styles[j]
            axes[row, 0].plot(res.t, res.velocity[run, :, j], **kw)
            if j > 0 or ring:  # a ring's column 0 is vehicle 1, whose gap is to vehicle N
                axes[row, 1].plot(res.t, res.spacing[run, :, j], **kw)
        active = getattr(res, "aeb_active", None)
        if active is not None:
            cols = np.asarray(active)
            cols = cols[:, :, None] if cols.ndim == 2 else cols
            for k, j in enumerate(cavs[: cols.shape[2]]):
                for t0, t1 in aeb_intervals(res.t, cols[run, :, k]):
                    for ax in axes[row]:
                        ax.axvspan(t0, t1, color=styles[j]["color"], alpha=0.3, lw=0,
                                   zorder=1, label="AEB active" if aeb_label else None)
                    aeb_label = False
        v_star = float(np.asarray(res.v_star).reshape(-1)[run])
        axes[row, 0].axhline(v_star, color="k", lw=0.6, ls=":")
        axes[row, 0].set_ylabel(f"{display_name(name)}\nvelocity (m/s)")
        axes[row, 1].set_ylabel("spacing (m)")
        if res.collided[run].any():
            axes[row, 1].set_title("collision", color=PALETTE.bound, fontsize=9)
    for ax in axes[-1]:
        ax.set_xlabel("time (s)")
        ax.set_xlim(float(items[0][1].t[0]), float(items[0][1].t[-1]))
    _legend_below(fig, axes.flat, ncols=6)
    return _save(fig, path, title, dpi=110)


@_styled
def plot_case_grid(
    results, path: str | Path, quantity: str = "velocity", xlim=(20.0, 45.0),
    title: str | None = None, run: int = 0,
) -> Path:  # fmt: skip
    """Figs. 10 / 12: one panel per controller (2 columns), velocity or spacing of every
    vehicle over ``xlim`` in the house colours (:func:`vehicle_style`; the paper draws the CAV
    red and the HDVs behind blue); panels share their axes, titled as in the paper ("Case A").

    Parameters
    ----------
    results : mapping of str to lcc_synth.simulation.results.SimResult
    path : str or Path
    quantity : {"velocity", "spacing"}
    xlim : (float, float)
        Time window shown (s).
    """
    import numpy as np

    plt = _pyplot()
    path = Path(path)
    items = list(results.items())
    ncol = 2 if len(items) > 1 else 1
    nrow = (len(items) + ncol - 1) // ncol
    fig, axes = plt.subplots(
        nrow, ncol, figsize=(5.2 * ncol, 2.8 * nrow + 0.4), sharex=True, sharey=True,
        squeeze=False, constrained_layout=True,
    )  # fmt: skip
    for ax, (name, res) in zip(axes.flat, items, strict=False):
        keep = (res.t >= xlim[0]) & (res.t <= xlim[1])
        t = res.t[keep]
        data = res.velocity if quantity == "velocity" else res.spacing
        for j in range(res.n_vehicles):
            if quantity == "spacing" and j == 0:
                continue
            ax.plot(t, data[run, keep, j], **{**vehicle_style(j, res.cav), "lw": 1.6})
        ref = res.v_star[run] if quantity == "velocity" else res.s_star[run]
        ax.axhline(float(np.asarray(ref)), color="k", lw=0.5, ls=":")
        ax.set_title(display_name(name))
    for ax in axes.flat[len(items):]:
        ax.set_visible(False)
    for ax in axes[-1]:
        ax.set_xlabel("time (s)")
    for ax in axes[:, 0]:
        ax.set_ylabel("velocity (m/s)" if quantity == "velocity" else "spacing (m)")
    _legend_below(fig, axes.flat[: len(items)])
    return _save(fig, path, title, dpi=110)


@_styled
def plot_snapshots(
    baseline, lcc, times, path: str | Path, title: str | None = None, run: int = 0,
    labels=("looking ahead only", "LCC"),
) -> Path:  # fmt: skip
    """Fig. 11: the string at several moments, velocity deviation of each vehicle against its
    position (upper row ``baseline``, lower row ``lcc``); head yellow, CAV blue, HDVs grey
    (the house colours); every panel shares the y-axis.

    Parameters
    ----------
    baseline, lcc : lcc_synth.simulation.results.SimResult
        Two runs of the same scenario.
    times : sequence of float
        Moments to draw (s); the nearest recorded sample is used.
    """
    import numpy as np

    plt = _pyplot()
    path = Path(path)
    times = list(times)
    fig, axes = plt.subplots(
        2, len(times), figsize=(2.9 * len(times), 4.6), sharey=True, squeeze=False,
        constrained_layout=True,
    )  # fmt: skip
    for row, res in enumerate((baseline, lcc)):
        for col, tq in enumerate(times):
            ax = axes[row, col]
            k = int(np.argmin(np.abs(res.t - tq)))
            p = res.position[run, k]
            dv = res.velocity[run, k] - res.v_star[run]
            x = p - p[res.cav]  # positions relative to the CAV
            ax.axhline(0.0, color="k", lw=0.5, ls="--")
            ax.plot(x[1:], dv[1:], color=PALETTE.hdv, lw=0.8, zorder=2)
            hdv = [j for j in range(1, res.n_vehicles) if j != res.cav]
            ax.scatter(x[hdv], dv[hdv], s=28, color=PALETTE.hdv, zorder=3, label="HDVs")
            ax.scatter(x[res.cav], dv[res.cav], s=44, color=PALETTE.cav, zorder=4, label="CAV")
            ax.scatter(x[0], dv[0], s=28, color=PALETTE.head, zorder=4, label="head vehicle")
            ax.set_title(f"t = {res.t[k]:.1f} s", fontsize=9)
            if row == 1:
                ax.set_xlabel("position rel. to CAV (m)")
        axes[row, 0].set_ylabel(f"{labels[row]}\nv − v* (m/s)")
    _legend_below(fig, axes[:1, :1].flat)
    return _save(fig, path, title, dpi=110)


@_styled
def plot_mpc_predictions(
    result,
    history,
    path: str | Path,
    every: float = 2.0,
    window: tuple[float, float] | None = None,
    s_min: float = 5.0,
    t_gap: float = 0.8,
    title: str | None = None,
    run: int = 0,
) -> Path:
    """The CAV's velocity and spacing with the MPC's predicted trajectories and the bound.

    Parameters
    ----------
    result : lcc_synth.simulation.results.SimResult
        The MPC's run.
    history : dict
        ``MPCController.history()`` of that run.
    path : str or Path
        Output PNG.
    every : float
        Draw the prediction made every ``every`` seconds.
    window : (float, float), optional
        Time range to draw (default the whole run).
    s_min, t_gap : float
        The absolute spacing bound ``s_0 >= s_min + t_gap v_0`` drawn on the spacing panel.
    """
    import numpy as np

    plt = _pyplot()
    path = Path(path)
    cav = result.cav
    j = result.m  # the CAV's block in the MPC's model (vehicles -m..n)
    t = result.t
    lo, hi = window if window is not None else (t[0], t[-1])
    sel = (t >= lo) & (t <= hi)
    fig, axes = plt.subplots(2, 1, figsize=(10, 6), sharex=True, constrained_layout=True)
    v0 = result.velocity[run, :, cav]
    s0 = result.spacing[run, :, cav]
    axes[0].plot(t[sel], result.velocity[run, sel, 0], **vehicle_style(0, cav))
    axes[0].plot(t[sel], v0[sel], **vehicle_style(cav, cav))
    axes[1].plot(t[sel], s0[sel], **{**vehicle_style(cav, cav), "label": None})
    axes[1].plot(t[sel], (s_min + t_gap * v0)[sel], color=PALETTE.bound, lw=1.0, ls="--",
                 label=f"bound {s_min:g} m + {t_gap:g} s * v0")  # fmt: skip
    th = history["t"]
    pt = history["pred_time"]
    step = max(1, int(round(every / (th[1] - th[0])))) if th.size > 1 else 1
    first = True
    for k in range(0, th.size, step):
        if not lo <= th[k] <= hi:
            continue
        pv = history["predicted_velocity"][run, k, :, j]
        ps = history["predicted_spacing"][run, k, :, j]
        if not np.all(np.isfinite(pv)):
            continue
        label = "MPC prediction" if first else None
        kw = {"color": "k", "lw": 0.7, "alpha": 0.55, "label": label}
        axes[0].plot(th[k] + pt, pv, **kw)
        if np.all(np.isfinite(ps)):
            axes[1].plot(th[k] + pt, ps, **kw)
        first = False
    axes[0].set_ylabel("velocity (m/s)")
    axes[1].set_ylabel("CAV spacing (m)")
    axes[1].set_xlabel("time (s)")
    for ax in axes:
        ax.set_xlim(lo, hi)
    _legend_below(fig, axes)
    return _save(fig, path, title, dpi=110)


@_styled
def plot_metric_bars(report, path: str | Path, title: str | None = None) -> Path:
    """Table II as bars: AAVE and fuel of every controller (error bars: spread over seeds),
    annotated with the reduction versus the baseline. ``report`` is what
    :func:`lcc_synth.cli.simulate.report` returns."""
    plt = _pyplot()
    path = Path(path)
    names = list(report)
    colors = controller_colors(names)
    fig, axes = plt.subplots(1, 2, figsize=(9.5, 3.6), constrained_layout=True)
    for ax, key, unit in ((axes[0], "aave", "AAVE (m/s)"), (axes[1], "fuel_ml", "fuel (mL)")):
        vals = [report[n][key] for n in names]
        errs = [report[n][f"{key}_std"] if report[n]["batch"] > 1 else 0.0 for n in names]
        bars = ax.bar([display_name(n) for n in names], vals, yerr=errs if any(errs) else None,
                      capsize=4, color=[colors[n] for n in names])  # fmt: skip
        pct = "aave_pct" if key == "aave" else "fuel_pct"
        for bar, n, v in zip(bars, names, vals, strict=True):
            red = report[n].get("reduction_vs_baseline")
            text = f"{v:.2f}" + (f"\n(-{red[pct]:.2f} %)" if red and red[pct] is not None
                                 else "\n(n/a)" if red else "")  # fmt: skip
            ax.annotate(text, (bar.get_x() + bar.get_width() / 2, v / 2), ha="center",
                        va="center", fontsize=8, color="white", fontweight="bold")
        ax.set_ylabel(unit)
        ax.set_ylim(0, max(vals) * 1.25)
        ax.grid(False, axis="x")
    return _save(fig, path, title, dpi=110)


@_styled
def plot_sweep_distributions(samples, path: str | Path, metrics=None, title: str | None = None):
    """Distributions of Monte Carlo metrics, one panel per metric, one box per controller.

    Parameters
    ----------
    samples : mapping of str to mapping of str to array
        ``{controller: {metric: values (one per scenario)}}``, e.g. a sweep's ``samples``;
        NaN values (runs that collided before the end of the window) are left out.
    path : str or Path
        Output PNG.
    metrics : mapping of str to str, optional
        ``{metric: axis label}`` to draw (default every metric of the first controller).

    Boxes span the 25th-75th percentiles, whiskers the 5th-95th, the dot is the mean.
    """
    import numpy as np

    plt = _pyplot()
    path = Path(path)
    names = list(samples)
    if metrics is None:
        metrics = {k: k for k in samples[names[0]]}
    keys = list(metrics)
    ncol = min(3, len(keys))
    nrow = -(-len(keys) // ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.2 * ncol, 3.2 * nrow), squeeze=False,
                             constrained_layout=True)
    for ax, key in zip(axes.flat, keys, strict=False):
        data = []
        for c in names:
            x = np.asarray(samples[c][key], dtype=float)
            data.append(x[np.isfinite(x)])
        ax.boxplot(data, whis=(5, 95), showfliers=False, medianprops={"color": "k"},
                   tick_labels=[display_name(c) for c in names])  # fmt: skip
        means = [d.mean() if d.size else np.nan for d in data]
        ax.plot(np.arange(1, len(names) + 1), means, "o", color=PALETTE.bound, ms=4)
        ax.set_title(metrics[key], fontsize=9)
        ax.grid(False, axis="x")
        ax.tick_params(axis="x", labelrotation=20, labelsize=8)
    for ax in list(axes.flat)[len(keys):]:
        ax.axis("off")
    return _save(fig, path, title, dpi=110)
