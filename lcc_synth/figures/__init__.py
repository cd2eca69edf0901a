"""Figure writers (matplotlib, Agg backend, imported inside each function).

Every function takes already computed results from the package's analysis modules and writes
one figure (PNG, PDF or SVG: the extension of the path picks the type); none of them computes
anything of its own. One palette and style serve every figure (and the Rerun recordings share
its vehicle colours, :mod:`lcc_synth.recording.core`): head vehicle yellow, CAV blue, HDVs
grey (those ahead of the CAV darker and dashed), controllers in :data:`PALETTE`'s
``controllers`` colours (never blue or yellow; the baseline grey). Rows or panels that show the
same quantity for different controllers share their y-axis; axes carry units; legends sit
outside the axes; names read as in the paper (:func:`display_name`). The profiles of a run
tell every vehicle apart (:func:`vehicle_styles`: each CAV its own colour and marker, the HDVs
a sequential colormap) and shade emergency braking (:func:`aeb_intervals`).

Submodules: :mod:`.style` (palette, names, rc settings), :mod:`.simulation` (runs),
:mod:`.analysis` (linear analysis and synthesis); everything public is importable from here.
"""

from lcc_synth.figures.analysis import (
    plot_as_run_front,
    plot_control_energy,
    plot_gamma_curves,
    plot_pareto_front,
    plot_region_maps,
)
from lcc_synth.figures.ring import plot_time_space
from lcc_synth.figures.simulation import (
    plot_case_grid,
    plot_metric_bars,
    plot_mpc_predictions,
    plot_profiles,
    plot_snapshots,
    plot_sweep_distributions,
)
from lcc_synth.figures.style import (
    CAV_MARKERS,
    PALETTE,
    Palette,
    aeb_intervals,
    controller_colors,
    curve_styles,
    display_name,
    vehicle_style,
    vehicle_styles,
)

__all__ = [
    "PALETTE",
    "Palette",
    "CAV_MARKERS",
    "display_name",
    "controller_colors",
    "curve_styles",
    "aeb_intervals",
    "vehicle_style",
    "vehicle_styles",
    "plot_pareto_front",
    "plot_as_run_front",
    "plot_control_energy",
    "plot_profiles",
    "plot_gamma_curves",
    "plot_sweep_distributions",
    "plot_case_grid",
    "plot_snapshots",
    "plot_metric_bars",
    "plot_region_maps",
    "plot_mpc_predictions",
    "plot_time_space",
]
