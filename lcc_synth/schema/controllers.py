"""Declarations of the ``[controllers.NAME]`` tables: one per controller ``type``, the MPC's
sub-tables, and the suite form of ``run`` and ``sweep`` (``type = "h2"``, per-layout
overrides). The MPC defaults are those of :mod:`lcc_synth.mpc.settings`' dataclasses (a test
compares them)."""

from __future__ import annotations

from dataclasses import MISSING, fields, replace

from lcc_synth.controllers.baselines import BASELINE_TYPES
from lcc_synth.schema.spec import REQUIRED, Derived, Key, Table

__all__ = ["TABLES"]

_CMDS = ("simulate", "sweep", "run")
_C = "controllers.NAME"

_TYPES = ("hdv", "static", "gains_file", "mpc", "deep_lcc", *BASELINE_TYPES)
_TYPE = Key("type", "string", "The controller.", REQUIRED, choices=_TYPES)
_SUITE_TYPE = Key("type", "string", "The controller; h2 is synthesised for each layout.",
                  REQUIRED, choices=(*_TYPES, "h2"))
_SAMPLE_TIME = Key("sample_time", "number", "Controller period (zero-order hold; a multiple of "
                   "[scenario].dt); absent: every step.", None, lo=0.0, lo_open=True, unit="s")
_START = Key("start", "number", "Switch-on time, before the run's last sample: before it "
              "every CAV drives with its HDV law (lcc_synth.controllers.switch); absent: from the "
              "start of the run.", None, unit="s")
_EQUILIBRIUM = Key("equilibrium", "string", "Errors from the nominal v*, s* (fixed) or from a "
                   "low-pass estimate of the speed of the vehicle ahead (not fd_lcc).", "fixed",
                   choices=("fixed", "estimated"))
_EQ_TAU = Key("equilibrium_tau", "number", 'Time constant of that estimate (only with '
              'equilibrium = "estimated"); absent: 1.0 s.', None, lo=0.0, lo_open=True, unit="s")
_FILTER = Key("measurement_filter", "number", "Time constant of a first-order low-pass on every "
              "received spacing and velocity (0: off).", 0.0, lo=0.0, unit="s")
_SEMANTICS = Key("semantics", "string", "replace: u = sum(gain * error); added: the CAV's HDV "
                 "law plus that sum.", "added", choices=("added", "replace"))
_GAINS = Key("gains", "table", "State name (s_i, v_i, -p_0) -> gain; missing states 0. "
             "kind = platoon / ring: one table per CAV input, [controllers.NAME.gains.u_i] "
             "with state name (s_j, v_j of positions) -> gain.", REQUIRED)

GENERIC = Table(_C, "A CAV controller of simulate: its type selects the keys (below); "
                'type = "h2" is synthesised for the [system] first (the h2 table).',
                ("simulate",), (_TYPE,))
SUITE = Table(
    _C,
    "A CAV controller of run and sweep: the keys of its type, plus h2 and per-layout overrides.",
    ("sweep", "run"),
    (_SUITE_TYPE,
     Key("layouts", "table", "Per-layout overrides [controllers.NAME.layouts.LAYOUT] (run "
         "only).", {}),
     Key("only_layouts", "any", "The layouts this controller is for (run only); "
         "absent: every layout. On the others it has no row.", None),
     Key("only_scenarios", "any", "The scenarios this controller is for (run only; on "
         "layouts of only_layouts); absent: every scenario. In the others it has no row, and "
         "it is built only for the layouts of the scenarios run.", None)),
    variant="suite",
)
LAYOUT_OVERRIDE = Table(
    f"{_C}.layouts.LAYOUT",
    "Keys of the controller's type replacing (tables: merged into) its base keys on that "
    "layout; the type cannot change.",
    ("run",),
    any_key=Key("KEY", "any", "A key of this controller's type.", None),
)
HDV = Table(_C, 'type = "hdv": the CAV drives with the nominal [hdv] law.', _CMDS,
            (_TYPE, _SAMPLE_TIME, _START), variant="hdv")
STATIC = Table(
    _C, 'type = "static": static state feedback, eq. (23).', _CMDS,
    (_TYPE,
     Key("kind", "string", "Linear model whose state names the gains use.",
         Derived("[system].kind"),
         choices=("lcc", "cf_lcc", "fd_lcc", "ccc", "platoon", "ring")),
     _SEMANTICS, _GAINS, _SAMPLE_TIME, _EQUILIBRIUM, _EQ_TAU, _FILTER, _START),
    variant="static",
)
GAINS_FILE = Table(
    _C, 'type = "gains_file": static gains from a JSON file of lcc-synth synthesize.', _CMDS,
    (_TYPE,
     Key("file", "string", "The gains file, relative to the problem file.", REQUIRED),
     _SAMPLE_TIME, _EQUILIBRIUM, _EQ_TAU, _FILTER, _START),
    variant="gains_file",
)
H2 = Table(
    _C, 'type = "h2": an H2 gain synthesised (simulate: for [system]; run and sweep: for each '
    "layout) from the keys of [synthesis], then run as a static gain with these keys.", _CMDS,
    (_SUITE_TYPE, _SAMPLE_TIME, _EQUILIBRIUM, _EQ_TAU, _FILTER, _START),
    variant="h2", includes=("synthesis",),
)

_MPC = "mpc"
MPC = Table(
    _C, 'type = "mpc": the safety-constrained MPC (lcc_synth.mpc), every key optional.', _CMDS,
    (_TYPE,
     Key("sample_time", "number", "Controller period; the simulator holds the command.", 0.1,
         lo=0.0, lo_open=True, unit="s"),
     Key("horizon", "integer", "Prediction steps N (at most 500).", 50, lo=1),
     Key("n_model", "integer", "HDVs behind that the MPC predicts; absent: all of [system].n "
         "(platoon, ring: not used, the joint MPC models every vehicle).", None, lo=0),
     Key("fallback_gains_file", "any", "Static fallback gain file (a path); absent: the "
         "paper's gain (platoon, ring: gains {u_i: {state: gain}}; absent: each CAV's HDV "
         "law).", None),
     Key("fallback", "string", "Another controller of the file (static, or h2 once "
         "synthesised) whose gain is the static fallback; not with fallback_gains_file.", None),
     Key("weights", "table", "Stage cost: [controllers.NAME.weights].", {}),
     Key("constraints", "table", "Bounds: [controllers.NAME.constraints].", {}),
     Key("prediction", "table", "Prediction model: [controllers.NAME.prediction].", {}),
     Key("solver", "table", "QP solver and its settings: [controllers.NAME.solver].", {}), _START),
    variant=_MPC,
)
MPC_WEIGHTS = Table(
    f"{_C}.weights", "MPC stage cost x'Qx + input u^2 + jerk (du)^2.", _CMDS,
    (Key("velocity", "number", "Weight on the velocity error of every vehicle.", 1.0, lo=0.0,
         unit="(m/s)⁻²"),
     Key("spacing", "number", "Weight on the spacing error of every HDV.", 0.5, lo=0.0,
         unit="m⁻²"),
     Key("spacing_cav", "number", "Weight on the CAV's own spacing error s_0 (platoon, ring: "
         "every CAV's); absent: spacing.", None, lo=0.0, unit="m⁻²"),
     Key("position", "number", "Weight on FD-LCC's -p_0 state (0: not regulated).", 0.0,
         lo=0.0),
     Key("input", "number", "Weight on the CAV acceleration (see input_on).", 1.0, lo=0.0,
         lo_open=True),
     Key("jerk", "number", "Weight on its change between steps.", 0.0, lo=0.0),
     Key("input_on", "string", "CF-LCC: the total CAV acceleration or the model input u_hat.",
         "total", choices=("total", "model")),
     Key("slack", "number", "Exact (l1) penalty on spacing-constraint violation, per m and "
         "step.", 100.0, lo=0.0),
     Key("slack_quadratic", "number", "Small quadratic slack term (keeps the QP strictly "
         "convex).", 1.0, lo=0.0)),
    variant=_MPC,
)
_SPACING = Key("spacing", "string", "Bound on each CAV's own spacing ahead: safe (absolute, "
               "s >= s_min + t_gap v) or equilibrium (the DeeP-LCC paper's: spacing_error on "
               "s - s*(v_eq), the equilibrium spacing of the estimated velocity).", "safe",
               choices=("safe", "equilibrium"))
_SPACING_ERROR = Key("spacing_error", "number list", 'Bounds [lo, hi] on s - s*(v_eq), lo < 0 '
                     '< hi (spacing = "equilibrium" only; the paper: [-15, 20]).',
                     [-15.0, 20.0], length=2, unit="m")
MPC_CONSTRAINTS = Table(
    f"{_C}.constraints", "MPC bounds: hard acceleration, soft spacing, ISO 15622 comfort.", _CMDS,
    (Key("a_min", "number", "Hard lower bound on the CAV's total acceleration.", -5.0,
         unit="m/s²"),
     Key("a_max", "number", "Hard upper bound on it.", 2.0, unit="m/s²"),
     Key("s_min", "number", "Soft safe spacing ahead: s_0 >= s_min + t_gap v_0 (absolute).",
         5.0, lo=0.0, unit="m"),
     Key("t_gap", "number", "Time gap of that bound.", 0.8, lo=0.0, unit="s"),
     Key("margin", "number", "The QP enforces the bounds this much tighter.", 0.1, lo=0.0,
         unit="m"),
     Key("spacing_ahead", "boolean", "Enforce the spacing ahead (needs a vehicle ahead).", True),
     Key("behind", "any", "A list of integers (not for platoon, ring): HDVs behind with soft "
         "bounds s_i >= s_min_behind + t_gap_behind v_i.", []),
     Key("s_min_behind", "number", "Safe spacing of those HDVs.", 5.0, lo=0.0, unit="m"),
     Key("t_gap_behind", "number", "Their time gap.", 0.8, lo=0.0, unit="s"),
     Key("jerk_scale", "number", "|a_k - a_{k-W}| <= jerk_scale * ISO 15622 limit * W Ts "
         "(0: off).", 0.9, lo=0.0, hi=1.0),
     Key("jerk_window", "number", "W Ts, in [sample_time, 10] when jerk_scale > 0 (1 s: ISO "
         "15622's average).", 1.0, lo=0.0, lo_open=True, unit="s"),
     _SPACING, _SPACING_ERROR),
    variant=_MPC,
)
MPC_PREDICTION = Table(
    f"{_C}.prediction", "How the MPC predicts the head vehicle and the equilibrium.", _CMDS,
    (Key("head", "string", "constant: the head velocity is held; accel: its measured "
         "acceleration is held for head_accel_hold.", "constant", choices=("constant", "accel")),
     Key("head_accel_hold", "number", "How long that acceleration is held.", 1.0, lo=0.0,
         unit="s"),
     Key("equilibrium", "string", "v_eq: a moving average of the head's speed or the fixed "
         "v_star; absent: fixed for fd_lcc, else moving_average.", None,
         choices=("moving_average", "fixed")),
     Key("equilibrium_window", "number", "Moving-average window.", 5.0, lo=0.0, lo_open=True,
         unit="s"),
     Key("relinearize", "boolean", "Re-linearise the HDV model when v_eq drifts.", False),
     Key("relinearize_threshold", "number", "... by more than this.", 1.0, lo=0.0,
         lo_open=True, unit="m/s"),
     Key("delay", "any", "HDV reaction delay in the prediction model (delay states, "
         "lcc_synth.mpc.delay): a number in [0, 5] for every HDV, or a list with one per "
         "HDV the MPC models, front to tail (single-CAV MPC only); 0: none.", 0.0,
         unit="s"),
     Key("cav_lag", "number", "The CAV's first-order actuator lag in the prediction model "
         "(state a_0, lcc_synth.mpc.lag; single-CAV MPC, not with delay); 0: none.", 0.0,
         lo=0.0, unit="s")),
    variant=_MPC,
)
MPC_SOLVER = Table(
    f"{_C}.solver", "QP solver of the MPC: OSQP (default) or DAQP, and OSQP's settings.", _CMDS,
    (Key("method", "string", "QP solver: osqp (ADMM with polishing, the default) or daqp (exact "
         "dense active set, lcc_synth.mpc.active_set).", "osqp", choices=("osqp", "daqp")),
     Key("eps_abs", "number", "Absolute tolerance (OSQP).", 1.0e-6, lo=0.0, lo_open=True),
     Key("eps_rel", "number", "Relative tolerance (OSQP).", 1.0e-6, lo=0.0),
     Key("max_iter", "integer", "Iteration limit.", 10000, lo=1),
     Key("polish", "boolean", "Polish the solution (OSQP).", True),
     Key("warm_start", "boolean", "Warm-start from the previous solve (OSQP; DAQP always "
         "starts from the previous active set).", True),
     Key("time_limit", "number", "Wall-clock limit per solve (0: none).", 0.0, lo=0.0,
         unit="s")),
    variant=_MPC,
)

_DEEP = "deep_lcc"
DEEP_LCC = Table(
    _C, 'type = "deep_lcc": data-enabled predictive LCC (lcc_synth.deeplcc), every key '
    "optional; its period is [controllers.NAME.data].dt.", _CMDS,
    (_TYPE,
     Key("t_ini", "integer", "Past samples Tini that fix the initial condition.", 20, lo=1),
     Key("horizon", "integer", "Prediction steps N (at most 200).", 50, lo=1, hi=200),
     Key("equilibrium", "string", "v*: a moving average of the head's speed or the fixed "
         "[system].v_star; absent: fixed for fd_lcc, else moving_average.", None,
         choices=("moving_average", "fixed")),
     Key("equilibrium_window", "number", "Moving-average window.", 0.5, lo=0.0, lo_open=True,
         unit="s"),
     Key("weights", "table", "Cost: [controllers.NAME.weights].", {}),
     Key("constraints", "table", "Bounds: [controllers.NAME.constraints].", {}),
     Key("solver", "table", "QP solver and its settings: [controllers.NAME.solver].", {}),
     Key("data", "table", "Offline data: [controllers.NAME.data].", {}), _START),
    variant=_DEEP,
)
DEEP_LCC_WEIGHTS = Table(
    f"{_C}.weights", "DeeP-LCC cost sum ||y||_Q^2 + ||u||_R^2 + lambda_g ||g||^2 + lambda_y "
    "||sigma_y||^2 + spacing slack.", _CMDS,
    (Key("velocity", "number", "Q on the velocity error of every vehicle behind the head.",
         1.0, lo=0.0, lo_open=True, unit="(m/s)⁻²"),
     Key("spacing", "number", "Q on the spacing error of every CAV.", 0.5, lo=0.0, unit="m⁻²"),
     Key("input", "number", "R on every CAV acceleration.", 0.1, lo=0.0, lo_open=True),
     Key("lambda_g", "number", "Regularisation of g; 0 (noise-free data only) restricts g to "
         "the data's row space instead.", 100.0, lo=0.0),
     Key("lambda_y", "number", "Penalty on the past-output slack sigma_y.", 1.0e4, lo=0.0,
         lo_open=True),
     Key("past_outputs", "string", "slack: Y_p g = y_ini + sigma_y (penalised by lambda_y); "
         "exact: Y_p g = y_ini, no slack (the noise-free form).", "slack",
         choices=("slack", "exact")),
     Key("slack", "number", "Exact (l1) penalty on spacing-constraint violation, per m and "
         "step.", 100.0, lo=0.0),
     Key("slack_quadratic", "number", "Small quadratic slack term (keeps the QP strictly "
         "convex).", 1.0, lo=0.0, lo_open=True)),
    variant=_DEEP,
)
DEEP_LCC_CONSTRAINTS = Table(
    f"{_C}.constraints", "DeeP-LCC bounds: hard acceleration, soft spacing of "
    "every CAV (as the MPC's).", _CMDS,
    (Key("a_min", "number", "Hard lower bound on every CAV acceleration.", -5.0, unit="m/s²"),
     Key("a_max", "number", "Hard upper bound on it.", 2.0, unit="m/s²"),
     Key("s_min", "number", "Soft safe spacing: s >= s_min + t_gap v (absolute).", 5.0,
         lo=0.0, unit="m"),
     Key("t_gap", "number", "Time gap of that bound.", 0.8, lo=0.0, unit="s"),
     Key("margin", "number", "The QP enforces the bound this much tighter.", 0.1, lo=0.0,
         unit="m"),
     _SPACING, _SPACING_ERROR),
    variant=_DEEP,
)
#: DeeP-LCC's OSQP iteration limit: past it the exact active-set solve takes over.
DEEP_MAX_ITER = 200
DEEP_LCC_SOLVER = Table(
    f"{_C}.solver", "QP solver of DeeP-LCC's reduced QP: OSQP (default) or DAQP, as the "
    "MPC's.", _CMDS,
    (*(replace(k, default=DEEP_MAX_ITER, meaning="Iteration limit (then the exact solve).")
       if k.name == "max_iter" else k for k in MPC_SOLVER.keys),
     Key("exact", "boolean", "When OSQP stops unsolved, solve the QP with DAQP (an exact "
         "active-set solver, through CasADi) before the fallback chain.", True)),
    variant=_DEEP,
)
DEEP_LCC_DATA = Table(
    f"{_C}.data", "DeeP-LCC's offline data: collected in the nonlinear simulator on the "
    "run's scenario (HDVs, noise, delays), perturbations replaced by the excitation.", _CMDS,
    (Key("T", "integer", "Number of data samples.", 2000, lo=1),
     Key("dt", "number", "Sample time of the data and period of the controller (a multiple "
         "of [scenario].dt).", 0.05, lo=0.0, lo_open=True, unit="s"),
     Key("seed", "integer", "Seed of the excitation.", 0, lo=0),
     Key("u_amplitude", "number", "CAV inputs i.i.d. U[-a, a].", 1.0, lo=0.0, lo_open=True,
         unit="m/s²"),
     Key("e_amplitude", "number", "Head velocity v* + U[-a, a].", 1.0, lo=0.0, lo_open=True,
         unit="m/s"),
     Key("v_star", "number", "Equilibrium velocity of the collection; absent: [system]."
         "v_star.", None, lo=0.0, lo_open=True, unit="m/s"),
     Key("hdv_accel_noise", "number", "HDV acceleration noise during collection; absent: "
         "[scenario].hdv_accel_noise.", None, lo=0.0, unit="m/s²"),
     Key("cache", "boolean", "Reuse / write the .npz data cache.", True),
     Key("cache_dir", "string", "Folder of the cache (relative to the working directory).",
         "results/deeplcc")),
    variant=_DEEP,
)

#: Meaning and unit of every baseline parameter (defaults and sources: the dataclasses of
#: lcc_synth.controllers.baselines, one source).
_BASELINE_MEANING = {
    "U": ("Target speed (Stern et al. 2018: the experiment's set speed).", "m/s"),
    "dx0": ("Gap offsets of the three boundaries (Stern et al. 2018).", "m"),
    "d": ("Decelerations of the three boundaries (Stern et al. 2018).", "m/s²"),
    "window": ("Window of the AV's mean speed U (Stern et al. 2018).", "s"),
    "g_l": ("Gap below which no catch-up speed is added.", "m"),
    "g_u": ("Gap above which the full catch-up speed is added (> g_l).", "m"),
    "v_catch": ("Catch-up speed.", "m/s"),
    "gamma": ("Width of the blend between target and leader speed.", "m"),
    "dx_s_min": ("Floor of the safe gap dx_s = max(2 dv, dx_s_min).", "m"),
    "k_s": ("Gain on the gap error (Milanés & Shladover 2014).", "1/s²"),
    "k_v": ("Gain on the speed difference (Milanés & Shladover 2014).", "1/s"),
    "h": ("Time gap (> 0).", "s"),
    "s0": ("Standstill gap.", "m"),
    "k_p": ("Gain on the spacing error (Ploeg et al. 2011).", "1/s²"),
    "k_d": ("Gain on its rate (Ploeg et al. 2011).", "1/s"),
    "r": ("Standstill distance.", "m"),
}
_LENGTH = Key("length", "number", "Vehicle length subtracted from the spacing to get the gap.",
              0.0, lo=0.0, unit="m")


def _baseline_table(kind: str, cls) -> Table:
    keys = []
    for f in fields(cls):
        meaning, unit = _BASELINE_MEANING[f.name]
        default = REQUIRED if f.default is MISSING else f.default
        if isinstance(default, tuple):
            keys.append(Key(f.name, "number list", meaning, list(default), lo=0.0,
                            length=len(default), unit=unit))
        else:
            keys.append(Key(f.name, "number", meaning, default, unit=unit))
    return Table(
        _C, f'type = "{kind}": {cls.__doc__.split(";")[0].split(":")[0]} (a baseline of '
        "the field, lcc_synth.controllers.baselines).", _CMDS,
        (_TYPE, *keys, _SAMPLE_TIME, _LENGTH, _START), variant=kind,
    )


BASELINES = tuple(_baseline_table(k, c) for k, c in BASELINE_TYPES.items())

TABLES = (GENERIC, SUITE, HDV, STATIC, GAINS_FILE, H2, LAYOUT_OVERRIDE, MPC, MPC_WEIGHTS,
          MPC_CONSTRAINTS, MPC_PREDICTION, MPC_SOLVER, DEEP_LCC, DEEP_LCC_WEIGHTS,
          DEEP_LCC_CONSTRAINTS, DEEP_LCC_SOLVER, DEEP_LCC_DATA, *BASELINES)  # fmt: skip
