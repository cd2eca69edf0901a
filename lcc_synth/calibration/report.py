"""The text report of a :class:`~lcc_synth.calibration.fit.Calibration` (``lcc-synth
calibrate``): per follower and pooled, the parameters (an unidentified one as ``~value?``, never
as a precise number), calibrated versus nominal RMSE in the pairwise and the platoon replay."""

from __future__ import annotations

from lcc_synth.calibration.fit import Calibration, Fit
from lcc_synth.calibration.replay import PARAMS

__all__ = ["format_report", "format_value"]


def format_value(fit: Fit, name: str) -> str:
    """A parameter as printed: 3 significant digits when identified, ``~x?`` when not (and a
    trailing ``|`` when it sits at a bound)."""
    value = fit.params[name]
    text = f"{value:.3g}" if fit.identified[name] else f"~{value:.2g}?"
    return text + ("|" if name in fit.at_bound else "")


def _row(cells: list[str], widths: list[int]) -> str:
    return "  ".join(c.rjust(w) for c, w in zip(cells, widths, strict=True)).rstrip()


def format_report(cal: Calibration) -> str:
    """The report of ``lcc-synth calibrate`` (see docs/guide/calibration.md)."""
    names = list(PARAMS[cal.model])
    lines = [
        f"calibration of {cal.model.upper()} on {cal.path}: {len(cal.followers)} followers, "
        f"{cal.samples} samples at {1 / cal.dt:.3g} Hz, vehicle length {cal.length:g} m, "
        f"{cal.starts} starts (seed {cal.seed})",
        "",
        "parameters (~x? = not identified by these data; | = at a bound)",
    ]
    head = ["vehicle", *names, "starts"]
    rows = [[str(f.index), *(format_value(f.fit, k) for k in names),
             f"{f.fit.starts_at_best}/{cal.starts}"] for f in cal.followers]  # fmt: skip
    rows.append(["pooled", *(format_value(cal.pooled, k) for k in names),
                 f"{cal.pooled.starts_at_best}/{cal.starts}"])  # fmt: skip
    widths = [max(len(r[j]) for r in [head, *rows]) for j in range(len(head))]
    lines += [_row(head, widths), _row(["-" * w for w in widths], widths)]
    lines += [_row(r, widths) for r in rows]
    lines += ["", "RMSE spacing (m) / speed (m/s): calibrated vs the paper's nominal OVM "
              "(alpha 0.6, beta 0.9, s_st 5, s_go 35, v_max 30)"]
    head = ["vehicle", "pairwise", "nominal", "platoon", "nominal", "data"]
    rows = []
    for f in cal.followers:
        rows.append([
            str(f.index),
            f"{f.fit.rmse_spacing:.2f} / {f.fit.rmse_velocity:.2f}",
            f"{f.nominal_rmse_spacing:.2f} / {f.nominal_rmse_velocity:.2f}",
            f"{f.platoon_rmse_spacing:.2f} / {f.platoon_rmse_velocity:.2f}",
            f"{f.nominal_platoon_rmse_spacing:.2f} / {f.nominal_platoon_rmse_velocity:.2f}",
            f"{f.data_rmse_m:.2f}",
        ])
    rows.append(["pooled", f"{cal.pooled.rmse_spacing:.2f} / {cal.pooled.rmse_velocity:.2f}",
                 "", "", "", ""])  # fmt: skip
    widths = [max(len(r[j]) for r in [head, *rows]) for j in range(len(head))]
    lines += [_row(head, widths), _row(["-" * w for w in widths], widths)]
    lines += [_row(r, widths) for r in rows]
    lines += [
        "",
        "pairwise: each follower behind its recorded leader; platoon: only vehicle 0 recorded, "
        "the followers simulated in a chain; data: RMS mismatch (m) of the recorded gap with "
        "the integral of the recorded speeds (a floor for the spacing RMSE).",
    ]
    flat = sorted({k for f in [*(x.fit for x in cal.followers), cal.pooled]
                   for k, ok in f.identified.items() if not ok})  # fmt: skip
    if flat:
        lines.append(f"not identified somewhere: {', '.join(flat)} (95 % interval wider than "
                     "a quarter of the bound range, or a flat direction; --json gives the "
                     "intervals)")  # fmt: skip
    return "\n".join(lines)
