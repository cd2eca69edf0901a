"""Figures of the linear analysis and synthesis: control energy (Fig. 5), |Gamma| curves
(Fig. 9), string-stable regions (Figs. 7, 8) and the sparsity Pareto front (house style:
:mod:`.style`)."""

from __future__ import annotations

from pathlib import Path

from lcc_synth.figures.style import (
    PALETTE,
    _legend_below,
    _pyplot,
    _save,
    _styled,
    curve_styles,
    display_name,
)


@_styled
def plot_control_energy(sweep, path: str | Path, reference=None) -> Path:
    """Fig. 5: ``lambda_min(W(t))`` and ``tr(W(t)^{-1})`` against the number of HDVs ``n``.

    Parameters
    ----------
    sweep : lcc_synth.analysis.energy.EnergySweep
        Result of :func:`lcc_synth.analysis.energy.energy_vs_size`; one line per horizon. A
        float64 sweep ends at the last size before ``W(t)`` became numerically singular (marked
        in the legend); a multiprecision one (``method = "mp"``) goes to ``n_max``.
    path : str or Path
        Output PNG.
    reference : EnergySweep, optional
        A second sweep drawn as open circles on the same axes (e.g. the float64 values next to
        the multiprecision lines: where both exist they coincide).

    The y-axes have no unit: ``W`` mixes the units of the states (m, m/s).

    Returns
    -------
    Path of the written file.
    """
    plt = _pyplot()
    path = Path(path)
    fig, (ax_l, ax_t) = plt.subplots(1, 2, figsize=(10, 4.4), sharex=True,
                                     constrained_layout=True)  # fmt: skip
    colors = dict(zip(sweep.reports, PALETTE.controllers, strict=False))
    method = {"double": "float64", "mp": "multiprecision"}
    for label_of, sw, fmt in ((None, sweep, ".-"), ("ref", reference, "o")):
        if sw is None:
            continue
        for t, reports in sw.reports.items():
            n = [r.n for r in reports]
            label = f"t = {t:g} s, {method.get(reports[0].method, '')}" if reports else ""
            stop = sw.singular_n(t)
            if stop is not None:
                label += f" (singular from n = {stop})"
            kw = {"color": colors.get(t, "k"), "label": label}
            if label_of == "ref":
                kw.update(mfc="none", ms=7, ls="none")
            ax_l.semilogy(n, [r.lambda_min for r in reports], fmt, **kw)
            ax_t.semilogy(n, [r.trace_inv for r in reports], fmt, **kw)
    ax_l.set_title(r"(a) $\lambda_{\min}(W(t))$")
    ax_t.set_title(r"(b) $\mathrm{tr}(W(t)^{-1})$")
    ax_l.set_ylabel(r"$\lambda_{\min}(W(t))$")
    ax_t.set_ylabel(r"$\mathrm{tr}(W(t)^{-1})$")
    for ax in (ax_l, ax_t):
        ax.set_xlabel("number of HDVs behind the CAV, n")
        ax.grid(True, which="both", alpha=0.3)
        ax.xaxis.get_major_locator().set_params(integer=True)
    _legend_below(fig, [ax_l], ncols=3)
    kinds = {r.kind for reports in sweep.reports.values() for r in reports}
    fig.suptitle(f"Control energy of {', '.join(display_name(k) for k in sorted(kinds))} (Fig. 5)")
    return _save(fig, path, dpi=120)


@_styled
def plot_gamma_curves(curves, omega, path: str | Path, title: str | None = None) -> Path:
    """``|Gamma(j omega)|`` (head-to-tail velocity transfer) of several linear designs.

    Parameters
    ----------
    curves : mapping of str to (magnitude, report)
        ``{label: (|Gamma| on omega, StringStabilityReport)}``, e.g. from
        :func:`lcc_synth.experiments.comparison.gamma_curves`; the legend gives each peak and
        verdict. A report with measured points (``omega``, ``ratio``: a controller that is not
        linear) is drawn as its points only (markers, no line: nothing was measured between
        them), each controller its own marker.
    omega : array_like
        Frequencies (rad/s).
    path : str or Path
        Output file; its extension picks the type (``.png``, ``.pdf``, ``.svg``).

    Axes: the frequency axis spans where the curves change: from a third of the lowest
    frequency at which a curve has moved :data:`GAMMA_FLOOR` from its low-frequency value (or
    the lowest measured point) to 1.5 times the frequency past which every curve has decayed
    below :data:`GAMMA_FLOOR` (or the last measured point); the y-axis spans the data; the
    legend (two compact columns) sits under the plot. A setting after ``" @ "`` in a label
    (e.g. a V2V latency) is dotted in the colour of its controller (:func:`curve_styles`).
    """
    import numpy as np

    from lcc_synth.analysis.string_stability import verdict_text

    plt = _pyplot()
    path = Path(path)
    omega = np.asarray(omega, dtype=float)
    rows = -(-len(curves) // 2)
    fig, ax = plt.subplots(figsize=(7.0, 4.0 + 0.2 * rows), constrained_layout=True)
    styles = curve_styles(list(curves))
    top, w_hi, w_lo = 1.0, float(omega[0]), float(omega[-1])
    for label, (mag, rep) in curves.items():
        name = " @ ".join([display_name(label.split(" @ ")[0]), *label.split(" @ ")[1:]])
        st = styles[label]
        if hasattr(rep, "ratio"):  # measured in the simulator (not linear): points only
            text = f"{name}: max {rep.gamma_peak:.3f} (measured)"
            ax.semilogx(rep.omega, rep.ratio, ls="none", marker=st["marker"], ms=6,
                        color=st["color"], mfc="none" if " @ " in label else st["color"],
                        mew=1.4, label=text, zorder=4)  # fmt: skip
            top = max(top, float(np.nanmax(rep.ratio)))
            w_hi = max(w_hi, float(np.max(rep.omega)))
            w_lo = min(w_lo, float(np.min(rep.omega)))
            continue
        text = f"{name}: peak {rep.gamma_peak:.3f} ({verdict_text(rep.verdict)})"
        ax.semilogx(omega, mag, lw=1.6, color=st["color"], ls=st["ls"], label=text)
        m = np.asarray(mag, dtype=float)
        live = np.flatnonzero(np.isfinite(m) & (m >= GAMMA_FLOOR))
        if live.size:
            w_hi = max(w_hi, float(omega[live[-1]]))
            top = max(top, float(np.nanmax(m)))
        moved = np.flatnonzero(np.isfinite(m) & (np.abs(m - m[0]) >= GAMMA_FLOOR))
        if moved.size:  # where the curve leaves its low-frequency value
            w_lo = min(w_lo, float(omega[moved[0]]))
    ax.axhline(1.0, color="k", lw=0.8, ls="--")
    ax.set_xlim(max(float(omega[0]), w_lo / 3.0), min(float(omega[-1]), 1.5 * w_hi))
    ax.set_ylim(0.0, 1.06 * top)
    ax.set_xlabel("ω (rad/s)")
    ax.set_ylabel("|Γ(jω)|, tail / head velocity (m/s per m/s)")
    ax.grid(True, which="both", alpha=0.3)
    _legend_below(fig, [ax], ncols=2)
    ax.set_title(title or "Head-to-tail transfer")
    return _save(fig, path, dpi=120)


#: |Γ| below which a curve counts as decayed, and the change from its low-frequency value
#: that counts as moving: the frequency axis of :func:`plot_gamma_curves` spans the rest.
GAMMA_FLOOR = 1e-3


@_styled
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
        cav = getattr(rm, "cav", None)  # an open platoon's map names its CAV
        of = "" if cav is None else f" of CAV {cav}"
        ax.set_xlabel(f"$\\mu_{{{i}}}${of} (1/s²)")
        ax.set_ylabel(f"$k_{{{i}}}${of} (1/s)")
        fixed = ", ".join(f"{k}={v:g}" for k, v in rm.fixed.items())
        sub = f"string stable {100 * rm.string_stable_fraction:.1f}% of grid"
        sep = ";\n" if len(fixed) > 40 else "; "  # a long list of fixed gains on its own line
        ax.set_title(f"{titles.get(name, name)}\n{sub}" + (f"{sep}{fixed}" if fixed else ""),
                     fontsize=9)
        ax.axhline(0, color="k", lw=0.4)
        ax.axvline(0, color="k", lw=0.4)
        ax.grid(False)
    for ax in list(axes.flat)[len(names):]:
        ax.axis("off")
    handles = [
        Patch(facecolor="#3b6fb6", label="string stable"),
        Patch(facecolor="#d62728", label="string stable: expansion over baseline"),
        Patch(facecolor="#ffffff", edgecolor="k", label="stable, not string stable"),
        Patch(facecolor="#d9d9d9", hatch="///", label="unstable"),
    ]
    _legend_below(fig, handles, [h.get_label() for h in handles])
    return _save(fig, path, dpi=120)



@_styled
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
        ax.plot([p["count"] for p in off], [p["h2"] for p in off], "x", color=PALETTE.hdv,
                label="other patterns found")
    ax.plot([p["count"] for p in front], [p["h2"] for p in front], "o-",
            color=PALETTE.controllers[0], label="Pareto front")
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
    ax.set_xlabel("vehicles heard besides the CAV (count)")
    ax.set_ylabel("true closed-loop H2 norm, weighted (–)")
    ax.xaxis.get_major_locator().set_params(integer=True)
    ax.margins(x=0.08, y=0.2)  # room for the annotations above and right of the points
    _legend_below(fig, [ax], ncols=3)
    ax.set_title(title or "Sparsity-promoting H2 design")
    return _save(fig, path, dpi=120)


def plot_as_run_front(points, path: str | Path, title: str | None = None) -> Path:
    """The as-run trade-off (:func:`lcc_synth.experiments.as_run_front.as_run_front`): peak
    ``|Gamma|`` as run (the larger of latency 0 and 0.1 s) against head_brake's AAVE, minimum
    gap and CAV 1 s jerk, one panel each; points that needed emergency braking or collided
    (head_brake or heterogeneous) are crosses, string-stable ones filled, today's ``h2`` black.

    Parameters
    ----------
    points : list of FrontPoint
        Its ``name``, ``point.peak``, ``string_stable`` and ``values()``.
    path : str or Path
        Output PNG.
    """
    from matplotlib.lines import Line2D

    plt = _pyplot()
    path = Path(path)
    cols = (("aave_head_brake", "AAVE head_brake (m/s)"),
            ("min_gap_head_brake", "minimum gap head_brake (m)"),
            ("jerk1s_head_brake", "CAV max 1 s jerk head_brake (m/s³)"))  # fmt: skip
    fig, axes = plt.subplots(1, 3, figsize=(11, 4.2), constrained_layout=True)
    green = PALETTE.controllers[0]
    for ax, (key, label) in zip(axes, cols, strict=True):
        for k, p in enumerate(points):
            v = p.values()
            bad = (v["aeb_head_brake"] > 0 or v["aeb_heterogeneous"] > 0
                   or any(r.get("collided") for r in p.rows.values()))  # fmt: skip
            color = "k" if p.name == "h2" else green
            ax.plot(p.point.peak, v[key], "x" if bad else "o", color=color,
                    mfc=color if p.string_stable else "none", ms=7)
            ax.annotate(p.name, (p.point.peak, v[key]), textcoords="offset points",
                        xytext=(4, 6 if k % 2 else -10), fontsize=7)
        ax.axvline(1.0, ls="--", color="k", lw=0.8)
        ax.set_xlabel("peak |Γ| as run, worst of latency 0 / 0.1 s (–)")
        ax.set_ylabel(label)
        ax.margins(x=0.2, y=0.15)
    handles = [Line2D([], [], ls="none", marker="o", mfc="none", color=green),
               Line2D([], [], ls="none", marker="x", color=green),
               Line2D([], [], ls="none", marker="o", color=green),
               Line2D([], [], ls="--", color="k", lw=0.8)]  # fmt: skip
    labels = ["no emergency braking", "emergency braking or a collision (either scenario)",
              "string stable as run (exact verdict)", "|Γ| = 1"]  # fmt: skip
    _legend_below(fig, handles, labels, ncols=4)
    return _save(fig, path, title=title or "string10: as-run peak |Γ| vs head brake", dpi=120)
