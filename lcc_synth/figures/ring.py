"""Time-space diagram of a ring road: every vehicle's position on the ring against time,
coloured by its speed (the Sugiyama ring benchmark; house style: :mod:`.style`)."""

from __future__ import annotations

from pathlib import Path

from lcc_synth.figures.style import _pyplot, _save, _styled, display_name

__all__ = ["plot_time_space"]


@_styled
def plot_time_space(
    results, path: str | Path, title: str | None = None, run: int = 0, every: int = 1
) -> Path:
    """Position on the ring (m, the road's: vehicle lengths included) against time, every
    vehicle a trace of dots coloured by its speed; one panel per controller, one shared
    colour scale; the CAV's trace is outlined black and the switch-on time dashed.

    Parameters
    ----------
    results : mapping of str to lcc_synth.simulation.results.SimResult
        ``{controller: result}`` of ring runs.
    path : str or Path
        Output PNG.
    title : str, optional
    run : int
        Batch member to draw.
    every : int
        Draw every ``every``-th recorded sample (>= 1).
    """
    import numpy as np

    plt = _pyplot()
    path = Path(path)
    items = list(results.items())
    vmax = max(float(np.nanmax(r.velocity[run])) for _, r in items)
    fig, axes = plt.subplots(len(items), 1, figsize=(9.0, 2.8 * len(items) + 0.6), sharex=True,
                             squeeze=False)  # fmt: skip
    sc = None
    for ax, (name, r) in zip(axes[:, 0], items, strict=True):
        C = float(r.circumference)
        t = r.t[::every]
        x = np.mod(r.position[run, ::every], C)
        v = r.velocity[run, ::every]
        tt = np.repeat(t[:, None], x.shape[1], axis=1)
        sc = ax.scatter(tt.ravel(), x.ravel(), c=v.ravel(), s=0.6, cmap="viridis", vmin=0.0,
                        vmax=vmax, rasterized=True, linewidths=0)  # fmt: skip
        for c in r.cavs:
            ax.scatter(t, x[:, c], s=0.8, c="black", linewidths=0, rasterized=True)
        start = (r.controller_info or {}).get("start")
        if start is not None:
            ax.axvline(float(start), color="black", ls="--", lw=0.8)
        ax.set_ylim(0.0, C)
        ax.set_ylabel("position on ring (m)")
        ax.set_title(display_name(name), loc="left")
    axes[-1, 0].set_xlabel("time (s)")
    cbar = fig.colorbar(sc, ax=axes[:, 0].tolist(), shrink=0.9)
    cbar.set_label("speed (m/s)")
    return _save(fig, path, title)
