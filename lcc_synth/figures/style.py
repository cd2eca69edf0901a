"""The house style of every figure: one palette, names as in the paper, rc settings, legends.

Head vehicle yellow, CAV blue, HDVs grey (the colours of the Rerun recordings,
:mod:`lcc_synth.recording.core`), HDVs ahead of the CAV darker and dashed; controllers in
:data:`PALETTE`'s ``controllers`` colours, which are never blue or yellow, baselines grey.

Figures that must tell every vehicle apart (the profiles of ``lcc-synth run``) use
:func:`vehicle_styles`: the head yellow, each CAV its own colour (``Palette.cavs``, the
first the recordings' blue) and marker (:data:`CAV_MARKERS`), the HDVs a sequential colormap
(:data:`HDV_COLORMAP`, dark purple at the front to orange at the back, never yellow or blue)
by position behind the head. :func:`curve_styles` gives the |Γ| curves one colour per
controller and, per controller, one line style and marker, so that no curve hides another.
"""

from __future__ import annotations

import functools
import re
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from lcc_synth.recording.core import COLOR_CAV, COLOR_HDV, COLOR_HEAD

__all__ = [
    "PALETTE",
    "Palette",
    "CAV_MARKERS",
    "HDV_COLORMAP",
    "display_name",
    "controller_colors",
    "curve_styles",
    "aeb_intervals",
    "vehicle_style",
    "vehicle_styles",
]

#: Markers of the CAVs, in order (each CAV its own).
CAV_MARKERS = ("o", "s", "^", "D", "v", "P", "X", "*")
#: Markers of the measured |Γ| points, one per controller (the CAVs' markers, in order).
POINT_MARKERS = CAV_MARKERS
#: The HDVs' sequential colormap (matplotlib name) and the part of it used: dark to light
#: without its yellow end (the head's colour).
HDV_COLORMAP = ("plasma", 0.0, 0.72)


@dataclass(frozen=True)
class Palette:
    """Colours (RGB in [0, 1]) of every figure."""

    head: tuple = tuple(c / 255 for c in COLOR_HEAD)
    cav: tuple = tuple(c / 255 for c in COLOR_CAV)
    hdv: tuple = tuple(c / 255 for c in COLOR_HDV)
    hdv_ahead: tuple = (0.35, 0.35, 0.35)
    baseline: tuple = (0.45, 0.45, 0.45)
    bound: tuple = (0.84, 0.15, 0.16)
    controllers: tuple = ("#2ca02c", "#d62728", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2",
                          "#17becf")  # fmt: skip
    cavs: tuple = (tuple(c / 255 for c in COLOR_CAV), "#17becf", "#2ca02c", "#000000",
                   "#8c564b", "#e377c2")  # fmt: skip


PALETTE = Palette()
_STYLE = {
    "axes.grid": True, "grid.alpha": 0.3, "axes.titlesize": 10, "axes.labelsize": 9,
    "xtick.labelsize": 8, "ytick.labelsize": 8, "legend.fontsize": 8, "legend.frameon": False,
    "figure.titlesize": 11,
}  # fmt: skip
_BASELINES = {"all_hdv", "hdv_only", "all HDVs", "HDV only", "looking ahead only"}
_NAMES = {"all_hdv": "all HDVs", "hdv_only": "HDV only", "fd_lcc": "FD-LCC", "cf_lcc": "CF-LCC",
          "h2": "H2", "mpc": "MPC"}  # fmt: skip


def display_name(name: str) -> str:
    """A controller or case name as the paper writes it: ``case_a`` -> ``Case A``, ``fd_lcc``
    -> ``FD-LCC``, ``all_hdv`` -> ``all HDVs``; other names unchanged."""
    if name in _NAMES:
        return _NAMES[name]
    m = re.fullmatch(r"case[_ ]?([a-z])", name, flags=re.IGNORECASE)
    return f"Case {m.group(1).upper()}" if m else name


def controller_colors(names) -> dict:
    """``{name: colour}``: baselines (all HDVs, HDV only) grey, the others the palette's
    controller colours in order."""
    out, i = {}, 0
    for name in names:
        if name in _BASELINES or display_name(name) in _BASELINES:
            out[name] = PALETTE.baseline
        else:
            out[name] = PALETTE.controllers[i % len(PALETTE.controllers)]
            i += 1
    return out


def vehicle_style(
    j: int, cav: int, cavs: tuple[int, ...] | None = None, ring: bool = False
) -> dict:
    """Line style of vehicle column ``j`` (0 head, ``cav`` the CAV): colour, width, dash, layer
    and legend label (one label per group: head, HDVs ahead, CAV, HDVs behind).

    Several CAVs (``cavs``, array columns): every one blue (label ``CAVs``), HDVs ahead of the
    first one dashed, the others grey. A ring (``ring``): no head; column 0 is vehicle 1, an
    HDV like the others (``HDVs``), the CAVs blue.
    """
    if ring:
        if j in (cavs or (cav,)):
            return {"color": PALETTE.cav, "lw": 2.0, "ls": "-", "zorder": 4,
                    "label": "AV" if j == min(cavs or (cav,)) else None}  # fmt: skip
        return {"color": PALETTE.hdv, "lw": 0.9, "ls": "-", "zorder": 2,
                "label": "HDVs" if j == 0 else None}  # fmt: skip
    if j == 0:
        return {"color": PALETTE.head, "lw": 1.8, "ls": "-", "zorder": 3, "label": "head vehicle"}
    if cavs is not None and len(cavs) > 1:
        if j in cavs:
            return {"color": PALETTE.cav, "lw": 2.0, "ls": "-", "zorder": 4,
                    "label": "CAVs" if j == cavs[0] else None}  # fmt: skip
        cav = cavs[0]
        if j > cav:
            first = min(k for k in range(cav + 1, j + 1) if k not in cavs)
            return {"color": PALETTE.hdv, "lw": 0.9, "ls": "-", "zorder": 2,
                    "label": "HDVs behind" if j == first else None}  # fmt: skip
    if j == cav:
        return {"color": PALETTE.cav, "lw": 2.0, "ls": "-", "zorder": 4, "label": "CAV"}
    if j < cav:
        return {"color": PALETTE.hdv_ahead, "lw": 1.0, "ls": "--", "zorder": 2,
                "label": "HDVs ahead" if j == 1 else None}  # fmt: skip
    return {"color": PALETTE.hdv, "lw": 0.9, "ls": "-", "zorder": 2,
            "label": "HDVs behind" if j == cav + 1 else None}  # fmt: skip


def vehicle_styles(
    n_vehicles: int, cavs: tuple[int, ...] | list[int], ring: bool = False
) -> list[dict]:
    """Line styles that tell every vehicle apart, one per array column (a pure function).

    Parameters
    ----------
    n_vehicles : int
        Columns of the run (the head is column 0 unless ``ring``).
    cavs : sequence of int
        Columns of the CAVs.
    ring : bool
        A ring road: no head; column 0 is an HDV like the others.

    Returns
    -------
    list of dict
        Matplotlib keywords per column: ``color``, ``lw``, ``ls``, ``zorder``, ``label`` and,
        for a CAV, ``marker``. The head yellow (label ``head vehicle``); CAV ``k`` colour
        ``PALETTE.cavs[k]`` and marker ``CAV_MARKERS[k]`` (label ``CAV (vehicle j)``); the HDVs
        :data:`HDV_COLORMAP` sampled evenly from front to back (label on the first and last:
        ``HDV j (front)``, ``HDV j (back)``; a ring numbers its vehicles from 1 and says
        ``first``, ``last``), dashed ahead of the first CAV.
    """
    from matplotlib import colormaps

    cavs = [int(c) for c in cavs]
    first = min(cavs) if cavs else n_vehicles
    hdvs = [j for j in range(n_vehicles) if j not in cavs and (ring or j > 0)]
    name, lo, hi = HDV_COLORMAP
    cmap = colormaps[name]
    shades = [lo + (hi - lo) * (i / max(len(hdvs) - 1, 1)) for i in range(len(hdvs))]
    number = 1 if ring else 0  # a ring's column 0 is vehicle 1; else the head is vehicle 0
    ends = ("first", "last") if ring else ("front", "back")
    out: list[dict] = []
    for j in range(n_vehicles):
        if j in cavs:
            k = cavs.index(j)
            out.append({"color": PALETTE.cavs[k % len(PALETTE.cavs)], "lw": 2.0, "ls": "-",
                        "zorder": 4, "marker": CAV_MARKERS[k % len(CAV_MARKERS)], "ms": 5,
                        "label": f"CAV (vehicle {j + number})"})  # fmt: skip
        elif j == 0 and not ring:
            out.append({"color": PALETTE.head, "lw": 1.8, "ls": "-", "zorder": 3,
                        "label": "head vehicle"})  # fmt: skip
        else:
            i = hdvs.index(j)
            label = None
            if i == 0:
                label = f"HDV {j + number} ({ends[0]})"
            elif i == len(hdvs) - 1:
                label = f"HDV {j + number} ({ends[1]})"
            out.append({"color": tuple(float(c) for c in cmap(shades[i])[:3]), "lw": 1.0,
                        "ls": "--" if (not ring and j < first) else "-", "zorder": 2,
                        "label": label})  # fmt: skip
    return out


def curve_styles(labels) -> dict:
    """``{label: matplotlib keywords}`` of |Γ| curves: one colour per controller (the part of
    the label before ``" @ "``, :func:`controller_colors`), a setting after ``" @ "`` dotted in
    the same colour; each measured controller (``measured`` in the keywords' caller) gets its
    own marker from ``POINT_MARKERS`` in the order of the labels (a pure function)."""
    base = {label: label.split(" @ ")[0] for label in labels}
    colors = controller_colors(dict.fromkeys(base.values()))
    out = {}
    for i, label in enumerate(labels):
        out[label] = {"color": colors[base[label]], "ls": ":" if " @ " in label else "-",
                      "marker": POINT_MARKERS[i % len(POINT_MARKERS)]}  # fmt: skip
    return out


def aeb_intervals(t, active) -> list[tuple[float, float]]:
    """The time intervals ``[start, end)`` over which ``active`` (one flag per sample of ``t``)
    holds: from the first sample of each run of flags to the sample after its last (the last
    sample's time at the end of the record)."""
    import numpy as np

    a = np.asarray(active, dtype=bool).reshape(-1)
    t = np.asarray(t, dtype=float).reshape(-1)
    if not a.any():
        return []
    edges = np.diff(np.concatenate([[0], a.astype(np.int8), [0]]))
    starts = np.flatnonzero(edges == 1)
    ends = np.flatnonzero(edges == -1)  # index after the last active sample
    return [(float(t[s]), float(t[min(e, t.size - 1)])) for s, e in zip(starts, ends,
                                                                          strict=True)]


def _styled(func):
    """Run a figure writer inside the house style (matplotlib rc settings, restored after)."""

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        import matplotlib

        matplotlib.use("Agg")
        with matplotlib.rc_context(_STYLE):
            return func(*args, **kwargs)

    return wrapper


def _pyplot():
    import matplotlib.pyplot as plt

    return plt


def _legend_below(fig, axes_or_handles, labels=None, ncols: int = 4):
    """One figure legend outside the axes, under them (unique labels, in drawing order)."""
    if labels is None:
        seen: dict = {}
        for ax in axes_or_handles:
            for h, lab in zip(*ax.get_legend_handles_labels(), strict=True):
                seen.setdefault(lab, h)
        handles, labels = list(seen.values()), list(seen)
    else:
        handles = axes_or_handles
    if handles:
        fig.legend(handles, labels, loc="outside lower center", ncols=min(ncols, len(handles)))


#: Pillow's options for PNG files: zlib level 3 instead of its default 6 writes the same
#: pixels in about 60 % of the time for 5-7 % more bytes (measured on the profiles of
#: ``lcc-synth run``: 0.11 -> 0.065 s CPU and 628 -> 671 kB for the largest).
PNG_OPTIONS = {"compress_level": 3}


def _save(
    fig, path: Path, title: str | None = None, dpi: int = 110, overwrite: bool = True
) -> Path:
    """Add the optional suptitle, write ``fig`` to ``path`` atomically (creating folders;
    :func:`lcc_synth.outputs.writing`: a reader never sees half a file; the caller named the
    file, so an existing one is replaced, as ``savefig`` would, unless ``overwrite`` is false:
    then the next free name ``NAME-2.png``), close it; returns the name written. A write error
    (a full disk) is a :class:`~lcc_synth.errors.FileError` naming ``path``."""
    import matplotlib.pyplot as plt

    from lcc_synth.errors import FileError
    from lcc_synth.outputs import writing

    path = Path(path)
    try:
        if title:
            fig.suptitle(title)
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise FileError.from_os(path.parent, err, "create") from None
        png = path.suffix.lower() == ".png"
        with writing(path, overwrite) as out, _layout_once(fig, png, dpi):
            fig.savefig(out.tmp, dpi=dpi, **({"pil_kwargs": PNG_OPTIONS} if png else {}))
    finally:
        plt.close(fig)
    return out.path


@contextmanager
def _layout_once(fig, png: bool, dpi: int):
    """Lay ``fig`` out once, for a raster file: with a layout engine, ``savefig`` draws the
    figure twice (a pass that only lays it out, with every artist drawn on a renderer that
    paints nothing, then the picture); here the engine runs once at the file's resolution and
    is switched off for the one draw of ``savefig`` (restored after). The positions are those
    ``savefig`` would compute, so the pixels are the same (``tests/test_figures.py``).
    Measured on the nine figures of ``lcc-synth run`` (``benchmarks/bench_figures.py``,
    fastest of 5, 2026-12-03): 4.68 -> 3.95 s CPU with the zlib level of
    :data:`PNG_OPTIONS`. A vector file (PDF, SVG: text measured at 72 dpi by its own renderer)
    keeps ``savefig``'s two passes."""
    import matplotlib

    engine = fig.get_layout_engine()
    if engine is None or not png:
        yield
        return
    dpi0 = fig.get_dpi()
    fig.set_dpi(dpi)
    engine.execute(fig)
    # no engine at all ("none" leaves a placeholder, for which savefig draws twice)
    with matplotlib.rc_context({"figure.autolayout": False,
                                "figure.constrained_layout.use": False}):  # fmt: skip
        fig.set_layout_engine(None)
    try:
        yield
    finally:
        fig.set_layout_engine(engine)
        fig.set_dpi(dpi0)
