"""PNG figure writers (matplotlib, Agg backend, imported inside each function).

Every function takes already computed results from the package's analysis modules and writes
one PNG; none of them computes anything of its own.
"""

from __future__ import annotations

from pathlib import Path

__all__ = [
    "plot_pareto_front",
    "plot_control_energy",
    "plot_profiles",
    "plot_gamma_curves",
    "plot_sweep_distributions",
    "plot_case_grid",
    "plot_snapshots",
    "plot_metric_bars",
    "plot_region_maps",
    "plot_mpc_predictions",
]


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: Path, title: str | None = None, dpi: int = 110) -> Path:
    """Add the optional suptitle, write ``fig`` to ``path`` (creating folders), close it."""
    import matplotlib.pyplot as plt

    if title:
        fig.suptitle(title)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return path


def plot_control_energy(sweep, path: str | Path) -> Path:
    """Fig. 5: ``lambda_min(W(t))`` and ``tr(W(t)^{-1})`` against the number of HDVs ``n``.

    Parameters
    ----------
    sweep : lcc_synth.analysis.energy.EnergySweep
        Result of :func:`lcc_synth.analysis.energy.energy_vs_size`; one curve per horizon, each
        ending at the last size before ``W(t)`` became numerically singular (marked in the legend).
    path : str or Path
        Output PNG.

    Returns
    -------
    Path of the written file.
    """
    plt = _pyplot()
    path = Path(path)
    fig, (ax_l, ax_t) = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True)
    for t, reports in sweep.reports.items():
        n = [r.n for r in reports]
        label = f"t = {t:g} s"
        stop = sweep.singular_n(t)
        if stop is not None:
            label += f" (W singular from n = {stop})"
        ax_l.semilogy(n, [r.lambda_min for r in reports], "o-", label=label)
        ax_t.semilogy(n, [r.trace_inv for r in reports], "o-", label=label)
    ax_l.set_title(r"(a) $\lambda_{\min}(W(t))$")
    ax_t.set_title(r"(b) $\mathrm{tr}(W(t)^{-1})$")
    for ax in (ax_l, ax_t):
        ax.set_xlabel("number of HDVs behind the CAV, n")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
        ax.xaxis.get_major_locator().set_params(integer=True)
    kinds = {r.kind for reports in sweep.reports.values() for r in reports}
    names = {"fd_lcc": "FD-LCC", "cf_lcc": "CF-LCC"}
    fig.suptitle(f"Control energy of {', '.join(names.get(k, k) for k in sorted(kinds))} (Fig. 5)")
    return _save(fig, path, dpi=120)


def plot_pareto_front(pareto, h2_full: float, path: str | Path, title: str | None = None) -> Path:
    """Sparsity Pareto front: vehicles the CAV hears (besides itself) vs true H2 norm.

    Parameters
    ----------
    pareto : list of dict
        The ``pareto`` entries of a synthesis report (``count``, ``h2``, ``on_front``,
        ``vehicles``), from :func:`lcc_synth.synthesis.sparsity.sparsity_sweep`.
    h2_full : float
        Unstructured optimum (every vehicle heard), drawn as a reference line.
    path : str or Path
        Output PNG.
    """
    plt = _pyplot()
    path = Path(path)
    fig, ax = plt.subplots(figsize=(6.5, 4), constrained_layout=True)
    off = [p for p in pareto if not p["on_front"]]
    front = sorted((p for p in pareto if p["on_front"]), key=lambda p: p["count"])
    if off:
        ax.plot([p["count"] for p in off], [p["h2"] for p in off], "x", color="0.6",
                label="other patterns found")
    ax.plot([p["count"] for p in front], [p["h2"] for p in front], "o-", label="Pareto front")
    def label(vs):
        if not vs:
            return "CAV only"
        if len(vs) > 2 and list(vs) == list(range(vs[0], vs[0] + len(vs))):
            return f"{vs[0]}..{vs[-1]}"
        return ",".join(str(v) for v in vs)

    for p in front:
        ax.annotate(label(p["vehicles"]), (p["count"], p["h2"]), textcoords="offset points",
                    xytext=(3, 5), fontsize=7, rotation=30)
    ax.axhline(h2_full, ls="--", color="k", lw=0.8, label="unstructured optimum")
    ax.set_xlabel("vehicles heard besides the CAV")
    ax.set_ylabel("true closed-loop H2 norm (after polishing)")
    ax.xaxis.get_major_locator().set_params(integer=True)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title(title or "Sparsity-promoting H2 design")
    return _save(fig, path, dpi=120)


def plot_profiles(results, path: str | Path, title: str | None = None, run: int = 0) -> Path:
    """Velocity and spacing of every vehicle over time, one row per controller.

    Parameters
    ----------
    results : mapping of str to lcc_synth.simulation.results.SimResult
        ``{controller: result}`` of one scenario (same layout for all).
    path : str or Path
        Output PNG.
    title : str, optional
    run : int
        Batch member to draw.

    Head vehicle yellow, CAV blue, HDVs grey (lighter further back), as in the paper's figures.
    """
    import numpy as np

    from lcc_synth.recording import vehicle_colors, vehicle_names

    plt = _pyplot()
    path = Path(path)
    items = list(results.items())
    fig, axes = plt.subplots(
        len(items), 2, figsize=(11, 2.3 * len(items) + 0.6), sharex=True, squeeze=False,
        constrained_layout=True,
    )
    for row, (name, res) in enumerate(items):
        colors = vehicle_colors(res.m, res.n) / 255.0
        labels = vehicle_names(res.m, res.n)
        order = [j for j in range(res.n_vehicles) if j != res.cav] + [res.cav]  # CAV on top
        for j in order:
            lw = 1.8 if j in (0, res.cav) else 0.9
            kw = {"color": colors[j], "lw": lw, "label": labels[j]}
            axes[row, 0].plot(res.t, res.velocity[run, :, j], **kw)
            if j > 0:
                axes[row, 1].plot(res.t, res.spacing[run, :, j], **kw)
        v_star = float(np.asarray(res.v_star).reshape(-1)[run])
        axes[row, 0].axhline(v_star, color="k", lw=0.6, ls=":")
        axes[row, 0].set_ylabel(f"{name}\nvelocity (m/s)")
        axes[row, 1].set_ylabel("spacing (m)")
        if res.collided[run].any():
            axes[row, 1].set_title("collision", color="r", fontsize=9)
        for ax in axes[row]:
            ax.grid(True, alpha=0.3)
    for ax in axes[-1]:
        ax.set_xlabel("time (s)")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    keep = [i for i, lab in enumerate(labels) if lab in ("head", "cav")]
    if keep:
        axes[0, 0].legend([handles[i] for i in keep], [labels[i] for i in keep], fontsize=8,
                          loc="lower right")
    return _save(fig, path, title, dpi=110)


def plot_gamma_curves(curves, omega, path: str | Path, title: str | None = None) -> Path:
    """``|Gamma(j omega)|`` (head-to-tail velocity transfer) of several linear designs.

    Parameters
    ----------
    curves : mapping of str to (magnitude, report)
        ``{label: (|Gamma| on omega, StringStabilityReport)}``, e.g. from
        :func:`lcc_synth.experiments.comparison.gamma_curves`; the legend gives each peak and
        verdict. A report with measured points (``omega``, ``ratio``: a controller that is not
        linear) is drawn as markers.
    omega : array_like
        Frequencies (rad/s).
    path : str or Path
        Output PNG.
    """
    from lcc_synth.analysis.string_stability import verdict_text

    plt = _pyplot()
    path = Path(path)
    fig, ax = plt.subplots(figsize=(6.5, 4), constrained_layout=True)
    for label, (mag, rep) in curves.items():
        verdict = verdict_text(rep.verdict)
        text = f"{label}: peak {rep.gamma_peak:.3f} ({verdict})"
        if hasattr(rep, "ratio"):  # measured in the simulator (not linear): points
            ax.semilogx(rep.omega, rep.ratio, "o--", ms=4, label=text)
        else:
            ax.semilogx(omega, mag, label=text)
    ax.axhline(1.0, color="k", lw=0.8, ls="--")
    ax.set_xlabel("ω (rad/s)")
    ax.set_ylabel("|Γ(jω)|  (head → tail velocity)")
    ax.grid(True, which="both", alpha=0.3)
    # below |Γ| = 1 at low frequency every curve is flat at 1: the legend hides nothing there
    ax.legend(fontsize=7, loc="lower left")
    ax.set_title(title or "Head-to-tail transfer")
    return _save(fig, path, dpi=120)


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
        ax.boxplot(data, whis=(5, 95), showfliers=False, tick_labels=names)
        means = [d.mean() if d.size else np.nan for d in data]
        ax.plot(np.arange(1, len(names) + 1), means, "o", color="C3", ms=4)
        ax.set_title(metrics[key], fontsize=9)
        ax.grid(True, axis="y", alpha=0.3)
        ax.tick_params(axis="x", labelrotation=20, labelsize=8)
    for ax in list(axes.flat)[len(keys):]:
        ax.axis("off")
    return _save(fig, path, title, dpi=110)


def plot_case_grid(
    results, path: str | Path, quantity: str = "velocity", xlim=(20.0, 45.0),
    title: str | None = None, run: int = 0,
) -> Path:  # fmt: skip
    """Figs. 10 / 12: one panel per controller (2 columns), velocity or spacing of every
    vehicle over ``xlim``; head yellow-grey, HDVs ahead dark grey, CAV red, HDVs behind blue
    (the paper's colours).

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
            if j == 0:
                kw = {"color": (0.75, 0.75, 0.75), "label": "head vehicle"}
            elif j < res.cav:
                kw = {"color": (0.35, 0.35, 0.35), "label": "HDVs ahead" if j == 1 else None}
            elif j == res.cav:
                kw = {"color": (0.96, 0.21, 0.49), "label": "CAV"}
            else:
                kw = {"color": (0.26, 0.47, 0.89), "label": "HDVs behind" if j == res.cav + 1
                      else None}  # fmt: skip
            ax.plot(t, data[run, keep, j], lw=1.6, **kw)
        ref = res.v_star[run] if quantity == "velocity" else res.s_star[run]
        ax.axhline(float(np.asarray(ref)), color="k", lw=0.5, ls=":")
        ax.set_title(name, fontsize=10)
        ax.grid(True, alpha=0.3)
    for ax in axes.flat[len(items):]:
        ax.set_visible(False)
    for ax in axes[-1]:
        ax.set_xlabel("t (s)")
    for ax in axes[:, 0]:
        ax.set_ylabel("velocity (m/s)" if quantity == "velocity" else "spacing (m)")
    axes.flat[0].legend(fontsize=7, loc="lower right")
    return _save(fig, path, title, dpi=110)


def plot_snapshots(
    baseline, lcc, times, path: str | Path, title: str | None = None, run: int = 0,
    labels=("looking ahead only", "LCC"),
) -> Path:  # fmt: skip
    """Fig. 11: the string at several moments, velocity deviation of each vehicle against its
    position (upper row ``baseline``, lower row ``lcc``); head black, CAV blue, HDVs grey.

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
            ax.plot(x[1:], dv[1:], color=(0.36, 0.16, 0.52), lw=0.8)
            hdv = [j for j in range(1, res.n_vehicles) if j != res.cav]
            ax.scatter(x[hdv], dv[hdv], s=28, color=(0.7, 0.7, 0.7), zorder=3)
            ax.scatter(x[res.cav], dv[res.cav], s=40, color=(0.0, 0.69, 0.94), zorder=4)
            ax.scatter(x[0], dv[0], s=14, color="k", zorder=4)
            ax.set_title(f"t = {res.t[k]:.1f} s", fontsize=9)
            ax.grid(True, alpha=0.3)
            if row == 1:
                ax.set_xlabel("position rel. to CAV (m)")
        axes[row, 0].set_ylabel(f"{labels[row]}\nv - v* (m/s)")
    return _save(fig, path, title, dpi=110)


def plot_metric_bars(report, path: str | Path, title: str | None = None) -> Path:
    """Table II as bars: AAVE and fuel of every controller (error bars: spread over seeds),
    annotated with the reduction versus the baseline. ``report`` is what
    :func:`lcc_synth.cli.simulate.report` returns."""
    plt = _pyplot()
    path = Path(path)
    names = list(report)
    fig, axes = plt.subplots(1, 2, figsize=(9.5, 3.6), constrained_layout=True)
    for ax, key, unit in ((axes[0], "aave", "AAVE (m/s)"), (axes[1], "fuel_ml", "fuel (mL)")):
        vals = [report[n][key] for n in names]
        errs = [report[n][f"{key}_std"] if report[n]["batch"] > 1 else 0.0 for n in names]
        bars = ax.bar(names, vals, yerr=errs if any(errs) else None, capsize=4,
                      color=["0.6"] + ["tab:blue"] * (len(names) - 1))  # fmt: skip
        pct = "aave_pct" if key == "aave" else "fuel_pct"
        for bar, n, v in zip(bars, names, vals, strict=True):
            red = report[n].get("reduction_vs_baseline")
            text = f"{v:.2f}" + (f"\n(-{red[pct]:.2f} %)" if red else "")
            ax.annotate(text, (bar.get_x() + bar.get_width() / 2, v / 2), ha="center",
                        va="center", fontsize=8, color="white", fontweight="bold")
        ax.set_ylabel(unit)
        ax.set_ylim(0, max(vals) * 1.25)
        ax.grid(True, axis="y", alpha=0.3)
    return _save(fig, path, title, dpi=110)


def plot_region_maps(maps, path: str | Path, baselines=None, titles=None, ncols: int = 2) -> Path:
    """Figs. 7-8: string-stable regions of one vehicle's gains ``(mu_i, k_i)``.

    Blue: head-to-tail string stable; white: plant stable only; hatched grey: asymptotically
    unstable. With a baseline map (same grid), the part of the string-stable region that the
    baseline already had is blue and the expansion red (Fig. 7(c)-(f)).

    Parameters
    ----------
    maps : mapping of str to lcc_synth.analysis.regions.RegionMap
        One panel per map, in order.
    path : str or Path
        Output PNG.
    baselines : mapping of str to RegionMap, optional
        ``{map name: baseline map}``.
    titles : mapping of str to str, optional
        Panel titles (default: the map names).
    ncols : int
        Panels per row.
    """
    import numpy as np
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    plt = _pyplot()
    path = Path(path)
    baselines = dict(baselines or {})
    titles = dict(titles or {})
    names = list(maps)
    ncols = max(1, min(ncols, len(names)))
    nrows = (len(names) + ncols - 1) // ncols
    fig, axes = plt.subplots(
        nrows, ncols, figsize=(4.2 * ncols, 3.8 * nrows), squeeze=False, constrained_layout=True
    )
    # 0 unstable, 1 stable, 2 string stable (kept), 3 string stable (expansion)
    cmap = ListedColormap(["#d9d9d9", "#ffffff", "#3b6fb6", "#d62728"])
    for ax, name in zip(axes.flat, names, strict=False):
        rm = maps[name]
        img = rm.labels.astype(int)
        base = baselines.get(name)
        if base is not None:
            img = np.where((img == 2) & (base.labels != 2), 3, img)
        dmu = (rm.mu[-1] - rm.mu[0]) / max(len(rm.mu) - 1, 1)
        dk = (rm.k[-1] - rm.k[0]) / max(len(rm.k) - 1, 1)
        extent = [rm.mu[0] - dmu / 2, rm.mu[-1] + dmu / 2, rm.k[0] - dk / 2, rm.k[-1] + dk / 2]
        ax.imshow(
            img.T, origin="lower", extent=extent, cmap=cmap, vmin=-0.5, vmax=3.5,
            interpolation="nearest", aspect="auto",
        )
        if np.any(rm.labels == 0):
            ax.contourf(
                rm.mu, rm.k, (rm.labels == 0).T.astype(float), levels=[0.5, 1.5],
                colors="none", hatches=["///"],
            )
        i = rm.vehicle
        ax.set_xlabel(f"$\\mu_{{{i}}}$")
        ax.set_ylabel(f"$k_{{{i}}}$")
        fixed = ", ".join(f"{k}={v:g}" for k, v in rm.fixed.items())
        sub = f"string stable {100 * rm.string_stable_fraction:.1f}% of grid"
        ax.set_title(f"{titles.get(name, name)}\n{sub}" + (f"; {fixed}" if fixed else ""),
                     fontsize=9)
        ax.axhline(0, color="k", lw=0.4)
        ax.axvline(0, color="k", lw=0.4)
    for ax in list(axes.flat)[len(names):]:
        ax.axis("off")
    handles = [
        Patch(facecolor="#3b6fb6", label="string stable"),
        Patch(facecolor="#d62728", label="string stable: expansion over baseline"),
        Patch(facecolor="#ffffff", edgecolor="k", label="stable, not string stable"),
        Patch(facecolor="#d9d9d9", hatch="///", label="unstable"),
    ]
    fig.legend(handles=handles, loc="outside lower center", ncols=4, fontsize=8)
    return _save(fig, path, dpi=120)


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
    axes[0].plot(t[sel], result.velocity[run, sel, 0], color="#d4a017", lw=1.5, label="head")
    axes[0].plot(t[sel], v0[sel], color="#1f5fbf", lw=1.8, label="CAV")
    axes[1].plot(t[sel], s0[sel], color="#1f5fbf", lw=1.8, label="CAV spacing")
    axes[1].plot(t[sel], (s_min + t_gap * v0)[sel], color="r", lw=1.0, ls="--",
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
        kw = {"color": "0.45", "lw": 0.8, "alpha": 0.8, "label": label}
        axes[0].plot(th[k] + pt, pv, **kw)
        if np.all(np.isfinite(ps)):
            axes[1].plot(th[k] + pt, ps, **kw)
        first = False
    axes[0].set_ylabel("velocity (m/s)")
    axes[1].set_ylabel("spacing (m)")
    axes[1].set_xlabel("time (s)")
    for ax in axes:
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8, loc="lower right")
        ax.set_xlim(lo, hi)
    return _save(fig, path, title, dpi=110)
