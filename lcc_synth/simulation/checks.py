"""What a scenario's values mean in its run, checked before any work.

* :func:`check_draw_bounds`: the heterogeneity half-widths as bounds (every value a draw can
  produce must be valid as a fixed value would be;
  :class:`~lcc_synth.simulation.scenario.Scenario` calls it when it is made);
* :func:`check_timing`: a reaction delay or a V2V latency as long as the run, a perturbation
  that would never act (:func:`lcc_synth.simulation.scenario_file.scenario_from` calls it on
  every scenario of a file);
* :func:`check_start`: a switch-on or start time at or after the run's last sample (also
  :func:`lcc_synth.experiments.spec.check_starts` for the controllers);
* :func:`check_ranges`: both ends of a sweep's ``[lo, hi]`` ranges
  (:func:`lcc_synth.experiments.sweep.load_sweep`).

Every error is a :class:`~lcc_synth.errors.ConfigError` naming the field (``scenario.*``; a
suite's loader renames it ``scenarios.NAME.*``) and what is allowed.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping
from typing import Any

import numpy as np

from lcc_synth.errors import ConfigError

__all__ = ["check_draw_bounds", "check_ranges", "check_start", "check_timing"]


def check_draw_bounds(
    cls: type, base: Mapping[str, np.ndarray], widths: Mapping[str, float], v_star: float
) -> None:
    """Every value a heterogeneity draw ``base ± w`` can produce must be valid, as a fixed value
    would be: the HDV model ``cls`` (its own checks) of every HDV's values with each drawn
    parameter at either end (alone, then all of them at their extremes together) must be valid
    and have an equilibrium at ``v_star``.

    Parameters
    ----------
    cls : type
        The HDV model (:class:`~lcc_synth.models.hdv.OVM`, :class:`~lcc_synth.models.hdv.IDM`).
    base : mapping of str to numpy.ndarray
        Every model parameter's value of every HDV before the draws.
    widths : mapping of str to float
        The half-width ``w > 0`` of each drawn parameter.
    v_star : float
        The equilibrium velocity.

    Raises
    ------
    ConfigError
        ``scenario.heterogeneity.KEY`` with its largest allowed half-width (by bisection) and
        the rule a larger one breaks; ``scenario.heterogeneity`` for half-widths valid one by one
        but not together.
    """

    def rule(values: dict[str, np.ndarray]) -> str | None:
        """``None`` when every model of ``values`` is valid, else the first violated
        rule (checked one HDV at a time for a readable message)."""
        try:
            cls(**values).equilibrium_spacing(v_star)
            return None
        except ConfigError:
            pass
        for j in range(next(iter(values.values())).size):
            try:
                cls(**{k: float(v[j]) for k, v in values.items()}).equilibrium_spacing(
                    v_star)  # fmt: skip
            except ConfigError as err:  # the rule, without the value ("got ...")
                return f"{err.field} {err.message.split(', got ')[0]}"
        return "an invalid HDV"  # pragma: no cover - the vector check agrees

    def spread(key: str, w: float) -> dict[str, np.ndarray]:
        return {k: np.concatenate([b - w, b + w]) if k == key else np.concatenate([b, b])
                for k, b in base.items()}  # fmt: skip

    if rule(base) is not None:
        return  # the nominal values themselves: reported where they are read
    for key, w in widths.items():
        broken = rule(spread(key, w))
        if broken is None:
            continue
        lo, hi = 0.0, w
        for _ in range(60):  # the largest valid half-width, by bisection
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if rule(spread(key, mid)) is None else (lo, mid)
        broken = rule(spread(key, hi))  # the rule that binds just beyond the limit
        shown = float(f"{lo:.6g}")
        op = "<=" if shown <= lo or rule(spread(key, shown)) is None else "<"
        b = base[key]
        at = f"{b.min():g}" if b.min() == b.max() else f"{b.min():g}..{b.max():g}"
        raise ConfigError(
            f"scenario.heterogeneity.{key}",
            f"must be {op} {shown:g} here: a draw U[-w, w] around the HDVs' {key} = {at} "
            f"can reach [{b.min() - w:g}, {b.max() + w:g}], and every value a draw can "
            f"produce must be valid as a fixed value is ({broken}), got {w:g}",
        )
    keys = list(widths)
    corners = [dict(zip(keys, signs, strict=True))
               for signs in itertools.product((-1.0, 1.0), repeat=len(keys))]  # fmt: skip
    joint = {k: np.concatenate([b + c.get(k, 0.0) * widths.get(k, 0.0) for c in corners])
             for k, b in base.items()}  # fmt: skip
    broken = rule(joint)
    if broken is not None:
        raise ConfigError(
            "scenario.heterogeneity",
            f"the half-widths {widths} are valid one by one, but draws of them together "
            f"can produce an invalid HDV ({broken}): narrow them",
        )


def check_start(field_name: str, start: float, sc: Any, what: str) -> None:
    """``start`` (a controller's switch-on time, a perturbation's start) must come before the
    run's last sample, else ``what`` would never act: a ConfigError naming ``field_name``
    (times within ``1e-6 dt`` are equal, as in the perturbations' windows)."""
    if float(start) >= sc.last_time - 1e-6 * sc.dt:
        raise ConfigError(field_name, f"must be before the run's last sample, t = "
                          f"{sc.last_time:g} s (t_start + duration - dt), got {start:g}: "
                          f"{what} would never act")  # fmt: skip


def check_timing(sc: Any) -> None:
    """Values valid one by one that mean nothing in this run (ConfigError naming the field):
    an HDV reaction delay (``mean + spread``) or a V2V latency as long as the run (``duration``;
    nothing that happens in it would reach the HDVs or the CAV), a perturbation that starts at
    or after the run's last sample or ends before its first (it would never act). Checked by
    :func:`lcc_synth.simulation.scenario_file.scenario_from` on every scenario of a file; a
    controller's ``start`` is checked where the controllers are read
    (:func:`lcc_synth.experiments.spec.check_starts`)."""
    duration = float(sc.duration)
    delay = float(np.max(np.asarray(sc.delay, dtype=float), initial=0.0))
    if delay >= duration:
        raise ConfigError("scenario.delay.mean", f"must be shorter than the run (duration = "
                          f"{duration:g} s), got {delay:g} s: the HDVs would react to nothing "
                          "that happens in it")  # fmt: skip
    if delay + sc.delay_spread >= duration:
        raise ConfigError("scenario.delay.spread", f"mean + spread must be shorter than the run "
                          f"(duration = {duration:g} s), got {delay:g} + {sc.delay_spread:g} s: "
                          "a drawn HDV would react to nothing that happens in it")  # fmt: skip
    if float(sc.v2v.latency) >= duration:
        raise ConfigError("scenario.v2v.latency", f"must be shorter than the run (duration = "
                          f"{duration:g} s), got {float(sc.v2v.latency):g} s: the CAV would "
                          "receive nothing sent during it")  # fmt: skip
    for i, p in enumerate(sc.perturbations):
        start, end, key = p.window()
        name = f"scenario.perturbations[{i}].{key}"
        check_start(name, start, sc, "the perturbation")
        if end <= sc.t_start:
            raise ConfigError(name, f"the perturbation's window [{start:g}, {end:g}] s ends "
                              f"before the run's first sample, t_start = {sc.t_start:g} s: it "
                              "would never act")  # fmt: skip


def check_ranges(sc: Any, ranges: Mapping[str, tuple[float, float]]) -> None:
    """Every value a range ``[lo, hi]`` (:func:`~lcc_synth.simulation.scenario.split_ranges`)
    can draw must be valid as a fixed value would be: the scenario ``sc`` holds the lower bounds
    (checked when it was read); here the scenario with every range at its upper bound is checked
    the same way (:class:`~lcc_synth.simulation.scenario.Scenario`, :func:`check_timing`; each
    rule is monotone in each drawn setting). A ConfigError names ``scenario.KEY`` and the
    range."""
    if not ranges:
        return
    from dataclasses import replace

    top = {key: hi for key, (_, hi) in ranges.items()}
    try:
        v2v = replace(sc.v2v, **{k.split(".", 1)[1]: v for k, v in top.items()
                                 if k.startswith("v2v.")})  # fmt: skip
        check_timing(replace(sc, v2v=v2v,
                             hdv_accel_noise=top.get("hdv_accel_noise", sc.hdv_accel_noise)))
    except ConfigError as err:
        key = err.field.removeprefix("scenario.")
        if key not in ranges:  # pragma: no cover - a rule on a setting no range draws
            raise
        lo, hi = ranges[key]
        raise ConfigError(err.field, f"the range [{lo:g}, {hi:g}] can draw {hi:g}, and every "
                          f"value it can draw must be valid: {err.message}") from None
