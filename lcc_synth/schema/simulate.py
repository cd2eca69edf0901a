"""Declarations of the common tables and of what ``simulate``, ``run`` and ``sweep`` read:
the top level, ``[hdv]``, ``[system]``, ``[scenario]`` and its sub-tables, the perturbations,
``[metrics]``, ``[sweep]``, ``[layouts.NAME]`` and ``[scenarios.NAME]``."""

from __future__ import annotations

from dataclasses import fields

from lcc_synth.models.hdv import IDM, OVM
from lcc_synth.models.linear import KINDS
from lcc_synth.models.platoon import PLATOON_KINDS
from lcc_synth.schema.spec import REQUIRED, Derived, Key, Table

#: appended to the meaning of the settings a sweep may draw per scenario
_SWEEP_RANGE = " A sweep may give [lo, hi]: each scenario draws U[lo, hi]."

__all__ = ["TABLES"]

_SIM = ("simulate", "sweep")
_SYSTEM_CMDS = ("simulate", "sweep", "synthesize", "analyze", "regions")

TOP = Table(
    "",
    "The top level of a problem file: a file may carry the tables of several commands (each "
    "reads its own); a key no command reads is an error.",
    ("all",),
    (
        Key("name", "string", "The problem's name (in outputs and recordings).",
            Derived("the file's stem")),
        Key("description", "string", "Free text about the problem.", ""),
        Key("hdv", "table", "The nominal HDV car-following model: [hdv].", {}),
        Key("system", "table", "Layout and equilibrium of the linear model: [system].", REQUIRED),
        Key("scenario", "table", "What simulate and sweep run: [scenario].", {}),
        Key("metrics", "table", "AAVE / fuel window and vehicles: [metrics].", {}),
        Key("controllers", "table", "The CAV controllers to compare: [controllers.NAME].",
            REQUIRED),
        Key("sweep", "table", "Scenario count and batching of sweep: [sweep].", {}),
        Key("layouts", "table", "The systems run compares on: [layouts.NAME].", REQUIRED),
        Key("scenarios", "table", "The scenarios of run: [scenarios.NAME].", REQUIRED),
        Key("synthesis", "table", "The gain design of synthesize: [synthesis].", REQUIRED),
        Key("analysis", "table", "Frequency grid of analyze: [analysis].", {}),
        Key("cases", "table", "The gains analyze studies: [cases.NAME].", {}),
        Key("regions", "table", "Grid and frequency defaults of regions: [regions].", {}),
        Key("maps", "table", "The stability maps of regions: [maps.NAME].", REQUIRED),
    ),
)

_HDV_MEANING = {
    "alpha": ("OVM headway gain (eq. 2).", "1/s"),
    "beta": ("OVM relative-velocity gain (eq. 2).", "1/s"),
    "s_st": ("OVM stopping spacing, < s_go.", "m"),
    "s_go": ("OVM free-flow spacing.", "m"),
    "v_max": ("OVM maximum speed.", "m/s"),
    "v0": ("IDM desired speed.", "m/s"),
    "T": ("IDM time headway, > 0.", "s"),
    "s0": ("IDM jam distance.", "m"),
    "a": ("IDM maximum acceleration.", "m/s²"),
    "b": ("IDM comfortable deceleration.", "m/s²"),
    "delta": ("IDM acceleration exponent.", ""),
}


def _model_keys(cls) -> tuple[Key, ...]:
    """The parameters of a car-following model, defaults from its dataclass (one source)."""
    out = []
    for f in fields(cls):
        if f.name == "name":
            continue
        meaning, unit = _HDV_MEANING[f.name]
        out.append(Key(f.name, "number", meaning, f.default, unit=unit))
    return tuple(out)


HDV = Table(
    "hdv",
    "The nominal nonlinear HDV model (read by lcc_synth.models.hdv.model_from_dict; the "
    "model checks its own parameters).",
    ("all",),
    (
        Key("model", "string", "The car-following model.", "ovm", choices=("ovm", "idm")),
        *_model_keys(OVM),
        *_model_keys(IDM),
    ),
)

SYSTEM = Table(
    "system",
    "The linear model family, the string's layout and its equilibrium.",
    _SYSTEM_CMDS,
    (
        Key("kind", "string", "Linear model family (Sec. II); platoon: a head and several "
            "CAVs anywhere; ring: N vehicles on a ring road.", "lcc",
            choices=(*KINDS, *PLATOON_KINDS)),
        Key("m", "integer", "HDVs ahead of the CAV (required for lcc and ccc; 0 for cf_lcc, "
            "fd_lcc).", 0, lo=0, hi=50),
        Key("n", "integer", "HDVs behind the CAV (required for lcc, cf_lcc, fd_lcc; 0 for ccc).",
            0, lo=0, hi=200),
        Key("v_star", "number", "Equilibrium velocity; s* follows from the HDV model (a ring "
            "with a circumference: derived from it).", 15.0, lo=0.0, lo_open=True, unit="m/s"),
        Key("size", "integer", "Vehicles behind the head (platoon) or on the ring (required "
            "for platoon and ring).", None, lo=1, hi=400),
        Key("cavs", "any", "Positions (1..size) of the CAVs of a platoon or ring, front to "
            "tail; [] for all HDVs.", []),
        Key("circumference", "number", "Ring length (vehicle lengths included); default the "
            "sum of the equilibrium spacings at v_star plus size x vehicle_length (give one of "
            "the two).", None, lo=0.0, lo_open=True, unit="m"),
        Key("hdv_values", "table", "Per-vehicle [hdv] parameters of a platoon or ring: "
            "[system.hdv_values].", {}),
        Key("vehicle_length", "number", "Length of every vehicle of a platoon or ring: the "
            "dynamics run in gap coordinates (a ring of circumference C as point vehicles on "
            "C - size x vehicle_length, exact for gap-based laws); positions in results, "
            "recordings and figures show the road of length C.", 0.0, lo=0.0, unit="m"),
    ),
)

SYSTEM_HDV_VALUES = Table(
    "system.hdv_values",
    "Per-vehicle values of [hdv] model parameters in the model of a platoon or ring (each "
    "HDV linearised at its own equilibrium; a CAV's entry is the HDV law it drives with as an "
    "HDV).",
    _SYSTEM_CMDS,
    any_key=Key("PARAMETER", "number list", "One value per position 1..size, front to tail.",
                REQUIRED, length=Derived("size")),
)

SCENARIO = Table(
    "scenario",
    "What simulate (and each draw of sweep) runs: integration, limits, draws, V2V and "
    "perturbations.",
    _SIM,
    (
        Key("dt", "number", "Integration step (checked against the loops' time constants).",
            0.01, lo=0.0, lo_open=True, unit="s"),
        Key("duration", "number", "Simulated time; steps = round(duration / dt).", 100.0,
            lo=0.0, lo_open=True, unit="s"),
        Key("t_start", "number", "Time label of the first sample.", 0.0, unit="s"),
        Key("a_min", "number", "Acceleration lower limit of every vehicle.", -5.0, hi=0.0,
            hi_open=True, unit="m/s²"),
        Key("a_max", "number", "Acceleration upper limit of every vehicle.", 2.0, lo=0.0,
            lo_open=True, unit="m/s²"),
        Key("cav_aeb", "boolean", "CAV emergency braking, eq. (29).", True),
        Key("hdv_aeb", "boolean", "Also apply eq. (29) to every HDV.", False),
        Key("seed", "integer", "Base seed of every random draw (scenario b uses [seed, b]).", 0,
            lo=0),
        Key("batch", "integer", "Scenarios run together (--seeds overrides).", 1, lo=1),
        Key("record_every", "integer", "Keep every k-th sample (metrics use kept samples).", 1,
            lo=1),
        Key("spacing_reference", "string", "Spacing errors the controllers see: s* for "
            "everyone, or each HDV's own equilibrium spacing.", "nominal",
            choices=("nominal", "own_equilibrium")),
        Key("hdv_accel_noise", "number",
            "Std of white acceleration noise on every HDV." + _SWEEP_RANGE, 0.0,
            lo=0.0, unit="m/s²"),
        Key("accel_noise_uniform", "number", "Half width w of a uniform acceleration noise "
            "U[-w, w] on every vehicle but the head (CAVs included), added after the limits "
            "and emergency braking (the DeeP-LCC paper's scheme).", 0.0, lo=0.0, unit="m/s²"),
        Key("cav_lag", "number", "First-order actuator lag tau of every CAV's acceleration, "
            "da/dt = (u - a) / tau: limits and emergency braking act on the command u, the CAV "
            "applies a (0: no lag, else >= dt).", 0.0, lo=0.0, unit="s"),
        Key("heterogeneity", "table", "Per-HDV parameter draws: [scenario.heterogeneity].", {}),
        Key("delay", "table", "HDV reaction delay: [scenario.delay].", {}),
        Key("v2v", "table", "What the CAV receives: [scenario.v2v].", {}),
        Key("perturbations", "any", "Prescribed motions: an array of tables "
            "[[scenario.perturbations]].", []),
        Key("initial", "string", "Initial state: every vehicle at its equilibrium at v_star, "
            'or "data": the speeds and spacings (headway - [system] vehicle_length, > 0 '
            'needed) at the first sample of the first type = "trajectory" perturbation\'s '
            "file, file vehicle k in column k (head, then front to tail; as many vehicles as "
            "the string; built-in simulator).", "equilibrium", choices=("equilibrium", "data")),
        Key("hdv_values", "table", "Explicit per-HDV model parameters: [scenario.hdv_values].",
            {}),
        Key("backend", "string", "The simulator: the built-in one, or SUMO (co-simulation "
            'through libsumo; pip install -e ".[sumo]"; [scenario.sumo]).', "builtin",
            choices=("builtin", "sumo")),
        Key("sumo", "table", "SUMO's car-following model and integration (backend = "
            '"sumo"): [scenario.sumo].', {}),
    ),
)

SUMO = Table(
    "scenario.sumo",
    "How backend = \"sumo\" runs: the HDVs' SUMO car-following model (parameters from the "
    "[hdv] IDM ones: v0 -> maxSpeed, T -> tau, s0 -> minGap, a -> accel, b -> decel, delta) "
    "and SUMO's integration scheme.",
    _SIM,
    (
        Key("car_following", "string", "SUMO's car-following model of the HDVs (needs [hdv] "
            'model = "idm").', "IDM", choices=("IDM", "EIDM", "Krauss")),
        Key("step_method", "string", "SUMO's position update: euler (semi-implicit, SUMO's "
            "default) or ballistic (mean speed).", "euler", choices=("euler", "ballistic")),
        Key("sigma", "number", "SUMO's driver imperfection (Krauss, EIDM; 0 for the IDM).",
            0.0, lo=0.0, hi=1.0),
        Key("vehicle_length", "number", "Vehicle length in SUMO (spacings are bumper-to-bumper "
            "gaps: it only lengthens the road).", 5.0, lo=0.0, lo_open=True, unit="m"),
    ),
)

HETEROGENEITY = Table(
    "scenario.heterogeneity",
    "Each HDV of each scenario gets nominal + U[-w, w] for every parameter listed.",
    _SIM,
    any_key=Key("PARAMETER", "number", "Half-width w of the uniform draw of this [hdv] model "
                "parameter (in its unit); every value nominal ± w must be valid as a fixed "
                "[hdv] value (checked as bounds, before any run).", 0.0, lo=0.0),
)

HDV_VALUES = Table(
    "scenario.hdv_values",
    "Explicit per-HDV values of [hdv] model parameters (the same in every scenario; draws are "
    "added on top).",
    _SIM,
    any_key=Key("PARAMETER", "number list", "One value per HDV, front to tail (m + n entries), "
                "for this [hdv] model parameter.", REQUIRED, length=Derived("m + n")),
)

DELAY = Table(
    "scenario.delay",
    "HDV reaction delay: delay_i = mean + U[-spread, spread], rounded to steps.",
    _SIM,
    (
        Key("mean", "number", "Mean reaction delay of the HDVs (mean + spread shorter than "
            "the run).", 0.0, lo=0.0, unit="s"),
        Key("spread", "number", "Half-width of its uniform draw.", 0.0, lo=0.0,
            hi=Derived("mean"), unit="s"),
        Key("model", "string", "full: every input is delayed; perception: spacing and relative "
            "speed are, own speed is current.", "full", choices=("full", "perception")),
    ),
)

V2V = Table(
    "scenario.v2v",
    "What the CAV receives from the other vehicles at every controller sample.",
    _SIM,
    (
        Key("loss_rate", "number", "Per-link packet-loss probability, or a number list with one "
            "entry per vehicle head..tail (m + n + 2; the CAV's is ignored)." + _SWEEP_RANGE,
            0.0, lo=0.0, hi=1.0),
        Key("latency", "number", "Age of received values (rounded to steps; shorter than the "
            "run)." + _SWEEP_RANGE,
            0.0, lo=0.0, unit="s"),
        Key("spacing_noise", "number", "Std of noise on received spacings." + _SWEEP_RANGE,
            0.0, lo=0.0, unit="m"),
        Key("velocity_noise", "number", "Std of noise on received velocities." + _SWEEP_RANGE,
            0.0, lo=0.0, unit="m/s"),
        Key("position_noise", "number", "Std of noise on received positions." + _SWEEP_RANGE,
            0.0, lo=0.0, unit="m"),
    ),
)

#: ``loss_rate`` as a list (the loader reads it so when the value is a list).
LOSS_RATE_LIST = Table(
    "scenario.v2v",
    "The per-vehicle form of loss_rate (a list instead of a number).",
    _SIM,
    (Key("loss_rate", "number list", "One loss probability per vehicle head..tail.", 0.0,
         lo=0.0, hi=1.0, length=Derived("m + n + 2")),),
    variant="list",
)

_P_TYPE = Key("type", "string", "The kind of motion.", REQUIRED,
              choices=("sine", "brake", "brake_profile", "accel_profile", "speed_profile",
                       "trajectory"))
_P_VEHICLE = Key("vehicle", "any", 'The vehicle driven: "head" or a paper index (-m..n); '
                 'kind = platoon: "head" or a position 1..size; ring: a position.', "head")
_P_START = Key("start", "number", "Start of the window (open interval start < t < end), "
               "before the run's last sample.",
               20.0, unit="s")
_P_DECEL = Key("decel", "number", "Braking acceleration, < 0.", -5.0, unit="m/s²")
_P_TIMES = Key("times", "number list", "Breakpoint times (required unless csv).", REQUIRED,
               unit="s")
_P_INTERP = Key("interpolation", "string", "step: the value holds until the next time; linear.",
                "step", choices=("step", "linear"))
_P_CSV = Key("csv", "string", "Two-column t,value file instead of times/values (relative to the "
             "problem file).", None)

_PERT = "scenario.perturbations"
PERTURBATION = Table(_PERT, "Each entry overrides one vehicle's acceleration while active.",
                     _SIM, (_P_TYPE,))
PERTURBATIONS = (
    PERTURBATION,
    Table(_PERT, "Section V-A: a = amplitude cos(2 pi (t - start) / period).", _SIM, (
        _P_TYPE, _P_VEHICLE,
        Key("amplitude", "number", "Acceleration amplitude (either sign).", 0.2, unit="m/s²"),
        Key("period", "number", "Period of the cosine.", 12.0, lo=0.0, lo_open=True, unit="s"),
        _P_START,
        Key("end", "number", "End of the window.", Derived("start + period"),
            lo=Derived("start"), unit="s"),
    ), variant="sine"),
    Table(_PERT, "Section V-B: a = decel for duration s.", _SIM, (
        _P_TYPE, _P_VEHICLE, _P_START,
        Key("duration", "number", "Braking time.", 1.0, lo=0.0, unit="s"),
        _P_DECEL,
    ), variant="brake"),
    Table(_PERT, "Brake, hold, recover, cruise.", _SIM, (
        _P_TYPE, _P_VEHICLE, _P_START, _P_DECEL,
        Key("decel_time", "number", "Braking time.", 2.0, lo=0.0, unit="s"),
        Key("hold_time", "number", "Time at a = 0 after braking.", 5.0, lo=0.0, unit="s"),
        Key("accel", "number", "Recovery acceleration, > 0.", 2.0, unit="m/s²"),
        Key("accel_time", "number", "Recovery time (0: none).", 5.0, lo=0.0, unit="s"),
    ), variant="brake_profile"),
    Table(_PERT, "Piecewise acceleration, active from times[0] to times[-1].", _SIM, (
        _P_TYPE, _P_VEHICLE, _P_TIMES,
        Key("values", "number list", "Accelerations at the times (required unless csv).",
            REQUIRED, unit="m/s²"),
        _P_CSV, _P_INTERP,
    ), variant="accel_profile"),
    Table(_PERT, "Piecewise speed the vehicle tracks within its acceleration limits.", _SIM, (
        _P_TYPE, _P_VEHICLE, _P_TIMES,
        Key("values", "number list", "Speeds at the times, >= 0 (required unless csv).",
            REQUIRED, unit="m/s"),
        _P_CSV, _P_INTERP,
    ), variant="speed_profile"),
    Table(_PERT, "The head replays a recorded speed (a trajectory file's column): its "
          "acceleration is the recorded speed's change over each step, not clipped by "
          "a_min / a_max; from the recorded initial speed it has the recorded speed at every "
          "sample time. After the recording it cruises.", _SIM, (
        _P_TYPE,
        Key("vehicle", "any", 'The vehicle driven: "head" only (open road).', "head"),
        Key("file", "string", "Trajectory file (relative to the problem file): t, v0, "
            "headway0, v1, headway1, ... (problems/data/ngsim_i80/README.md).", REQUIRED),
        Key("column", "string", "The speed column replayed, v<k> of the file.", "v0"),
        Key("interpolation", "string", "Speed between samples: linear, or previous (held "
            "until the next sample).", "linear", choices=("linear", "previous")),
        Key("start", "number", "Simulation time of the recording's first sample.", 0.0,
            unit="s"),
    ), variant="trajectory"),
)

METRICS = Table(
    "metrics",
    "The window and vehicles of AAVE and fuel, and the baseline of reductions.",
    ("simulate", "sweep", "run"),
    (
        Key("window", "number list", "Closed interval of sample times of AAVE and fuel, inside "
            "the simulated time.", [20.0, 40.0], length=2, unit="s"),
        Key("vehicles", "any", 'Vehicles averaged: "cav_and_behind", "first_cav_and_behind" '
            '(the first CAV and every vehicle behind it; on a ring both mean every vehicle), '
            '"all" (head included), "hdvs" or a list of paper indices (platoon, ring: '
            'positions).', "cav_and_behind"),
        Key("accel_smoothing", "integer", "Fuel: smooth every acceleration by a centred "
            "moving average of this many recorded samples first (odd; 1: none; the DeeP-LCC "
            "paper: 9).", 1, lo=1, hi=1001),
        Key("baseline", "string", "A controller name: report reductions versus it (not in "
            "run).", None),
        Key("phases", "table", "Fuel over several windows of the same run: {name = [t0, t1], "
            "...} (s, closed as window, inside the simulated time); reported as "
            "fuel_ml_phases (and fuel_phases_pct versus the baseline).", None),
    ),
)

SWEEP = Table(
    "sweep",
    "How many random scenarios sweep draws and how many run per batch.",
    ("sweep",),
    (
        Key("count", "integer", "Scenarios (--count overrides).", 100, lo=1, hi=10_000_000),
        Key("batch_size", "integer", "Most scenarios per worker batch (a task); fewer when the "
            "count is small for the workers, so that every worker has tasks (--batch-size "
            "overrides, exactly).", 50, lo=1, hi=100_000),
    ),
)

LAYOUTS = Table(
    "layouts.NAME",
    "A system run compares on: the keys of [system], with [hdv] shared.",
    ("run",),
    includes=("system",),
)

SCENARIOS = Table(
    "scenarios.NAME",
    "A scenario of run: the keys of [scenario] plus these.",
    ("run",),
    (
        Key("layout", "string", "The [layouts.NAME] it runs on.", REQUIRED,
            choices=Derived("the [layouts] names")),
        Key("title", "string", "Heading in tables and figures.", ""),
        Key("metrics", "table", "Keys of [metrics] overriding the file's for this scenario "
            "(no baseline).", {}),
    ),
    includes=("scenario",),
)

TABLES = (TOP, HDV, SYSTEM, SYSTEM_HDV_VALUES, SCENARIO, SUMO, HETEROGENEITY, HDV_VALUES, DELAY,
          V2V, LOSS_RATE_LIST, *PERTURBATIONS, METRICS, SWEEP, LAYOUTS, SCENARIOS)  # fmt: skip
