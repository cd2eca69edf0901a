"""PNG figure writers (matplotlib, Agg backend, imported inside each function).

Every function takes already computed results from the package's analysis modules and writes
one PNG; none of them computes anything of its own.
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["plot_pareto_front", "plot_control_energy"]


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_control_energy(sweep, path: str | Path) -> Path:
    """Fig. 5: ``lambda_min(W(t))`` and ``tr(W(t)^{-1})`` against the number of HDVs ``n``.

    Parameters
    ----------
    sweep : lcc_synth.energy.EnergySweep
        Result of :func:`lcc_synth.energy.energy_vs_size`; one curve per horizon, each ending
        at the last size before ``W(t)`` became numerically singular (marked in the legend).
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
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


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
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
