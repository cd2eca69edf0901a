"""Declarations of what ``synthesize``, ``analyze`` and ``regions`` read: ``[synthesis]`` and
its sub-tables (also the keys of an ``h2`` suite controller), ``[analysis]``, ``[cases.NAME]``,
``[regions]`` and ``[maps.NAME]``. The H2 weight defaults are those of
:class:`lcc_synth.synthesis.h2.Weights` (a test compares them)."""

from __future__ import annotations

from lcc_synth.models.gains import GAIN_MAX
from lcc_synth.schema.spec import REQUIRED, Derived, Key, Table

__all__ = ["TABLES"]

_SYN = ("synthesize",)  # and the h2 controllers of run and sweep
_SEM = ("added", "replace")
_OMEGA = "rad/s"

SYNTHESIS = Table(
    "synthesis",
    "The H2 / LMI gain design (also the keys of an h2 controller of run and sweep).",
    _SYN,
    (
        Key("design", "string", "full_state (Riccati / LMI), structured (an information "
            "pattern), sparsity (promote sparse gains), string_stable (H2 with a string-"
            "stability LMI).", "structured",
            choices=("full_state", "structured", "sparsity", "string_stable")),
        Key("semantics", "string", "How the gain enters the command (eq. 23; fd_lcc: replace "
            "only).", Derived("replace for fd_lcc, cf_lcc, platoon and ring, else added"),
            choices=_SEM),
        Key("pattern", "any", 'Vehicles heard besides the CAV: "all" or a list of paper '
            "indices in [-m, n] (structured, string_stable).", "all"),
        Key("method", "string", "full_state: riccati | lmi; the others: lmi (convex "
            "restriction + polish) | direct (platoon, ring: sparsity direct only).",
            Derived("riccati for full_state, else lmi (platoon, ring: direct)"),
            choices=Derived("riccati, lmi for full_state; lmi, direct otherwise; platoon and "
                            "ring: direct for sparsity")),
        Key("cross_check", "boolean", "full_state: also solve the other method and compare.",
            Derived("true for one CAV, false for platoon and ring")),
        Key("tol", "number", "Polishing tolerance (relative gradient norm).", 1e-7, lo=0.0,
            hi=1e-2, lo_open=True),
        Key("cav_lag", "number", "The CAVs' first-order actuator lag tau in the design plant "
            "(a state a_i per CAV, not fed back; full_state, structured, string_stable; "
            "platoon / ring: full_state, structured, robust; 0: none).", 0.0, lo=0.0,
            unit="s"),
        Key("max_iter", "integer", "Polishing iterations.", 500, lo=1, hi=100000),
        Key("band", "integer", "structured lmi: coupling range (vehicles) of the non-heard "
            "block of X in the convex restriction (wider = tighter).", 4, lo=0, hi=50),
        Key("weights", "table", "Performance and disturbance weights: [synthesis.weights].", {}),
        Key("sparsity", "table", "design = sparsity: [synthesis.sparsity].", {}),
        Key("string", "table", "design = string_stable (one CAV, open platoon): "
            "[synthesis.string].", {}),
        Key("baseline", "table", "Hand-picked gains to compare with: [synthesis.baseline].",
            {}),
        Key("as_run", "any", "Design the loop as it runs: true, false or the table "
            "[synthesis.as_run] (true: its defaults).", False),
        Key("comm_range", "integer", "platoon, ring (structured; string_stable on an open "
            "platoon): every CAV hears the R "
            "vehicles ahead of it and the R behind it, itself included (the ring wraps "
            "around); 0 = decentralised (itself only); absent: every vehicle.", None, lo=0,
            hi=10000),
        Key("patterns", "table", "platoon, ring (structured; string_stable on an open "
            "platoon): per-CAV heard positions "
            "[synthesis.patterns] (override comm_range).", {}),
        Key("robust", "table", "platoon, ring, and lcc / cf_lcc / ccc (full_state, "
            "structured; any method): one gain for sampled HDV parameter sets "
            "[synthesis.robust].", {}),
    ),
)

PATTERNS = Table(
    "synthesis.patterns",
    "platoon, ring: the vehicles each CAV hears (structured design).",
    _SYN,
    any_key=Key("u_I", "number list", "CAV I's heard vehicle positions, integers in [1, size] "
                "(the CAV itself is always heard).", None, lo=1.0),
)

ROBUST = Table(
    "synthesis.robust",
    "platoon, ring, and one CAV behind a head vehicle (lcc, cf_lcc, ccc; designed on its "
    "one-CAV platoon): the robust multi-model design over sampled HDV parameters (OVM).",
    _SYN,
    (
        Key("samples", "integer", "Number of sampled members.", 20, lo=1, hi=1000),
        Key("seed", "integer", "Seed of numpy.random.default_rng.", 0, lo=0, hi=2**32 - 1),
        Key("objective", "string", "Minimise the mean or the (smooth) worst true H2 norm over "
            "the members.", "mean", choices=("mean", "worst")),
        Key("alpha", "number list", "[lo, hi] of each vehicle's uniform alpha draw; absent: "
            "nominal.", None, length=2, lo=0.0, unit="1/s"),
        Key("beta", "number list", "[lo, hi] of each vehicle's uniform beta draw; absent: "
            "nominal.", None, length=2, lo=0.0, unit="1/s"),
        Key("s_go", "number list", "[lo, hi] of each vehicle's uniform s_go draw; absent: "
            "nominal.", None, length=2, lo=0.0, unit="m"),
    ),
)

WEIGHTS = Table(
    "synthesis.weights",
    "Weights of the H2 problem (lcc_synth.synthesis.h2.Weights).",
    _SYN,
    (
        Key("q_s", "number", "Weight on every spacing error squared.", 1.0, lo=0.0, lo_open=True),
        Key("q_s0", "number", "Weight on the CAV's own spacing error s_0 (LCC, CF-LCC); "
            "absent: q_s.", None, lo=0.0, lo_open=True),
        Key("q_v", "number", "Weight on every velocity error squared.", 1.0, lo=0.0, lo_open=True),
        Key("q_a", "number", "Weight on every HDV's acceleration squared (smooth driving / "
            "fuel proxy).", 0.0, lo=0.0),
        Key("q_p", "number", "Weight on FD-LCC's -p_0 when position = weight (> 0 then).", 0.1,
            lo=0.0),
        Key("r", "number", "Weight on the gain's input squared.", 1.0, lo=0.0, lo_open=True),
        Key("head", "number", "Weight of the head-vehicle velocity disturbance (> 0 for "
            "string_stable; head and accel not both 0).", 0.0, lo=0.0),
        Key("accel", "number", "Weight of the acceleration noise on every velocity state (> 0 for "
            "fd_lcc).",
            1.0, lo=0.0),
        Key("position", "string", "FD-LCC position state: drop it or weight it with q_p.",
            "drop", choices=("drop", "weight")),
    ),
)

SPARSITY = Table(
    "synthesis.sparsity",
    "design = sparsity: the penalty sweep and the chosen gain.",
    _SYN,
    (
        Key("gammas", "number list", "Penalties; absent: n_gamma log-spaced values times J*.",
            None, lo=0.0),
        Key("n_gamma", "integer", "Number of penalties when gammas is absent.", 12, lo=2, hi=60),
        Key("reweight", "boolean", "Group weights from the unstructured optimum.", True),
        Key("rho", "number", "ADMM penalty parameter.", 10.0, lo=0.0, lo_open=True),
        Key("max_loss", "number", "Chosen gain: fewest vehicles with H2 <= (1 + max_loss) H2*.",
            0.01, lo=0.0, hi=10.0),
    ),
)

STRING = Table(
    "synthesis.string",
    "design = string_stable: the H-infinity bound and its polishing.",
    _SYN,
    (
        Key("gamma", "number", "H-infinity bound on head -> tail.", 1.0, lo=1.0, hi=100.0),
        Key("polish_steps", "integer", "String-stable-feasible polishing iterations.", 200,
            lo=0, hi=100000),
        Key("margin", "number", "Relative string-stability margin every polishing step keeps.",
            1e-4, lo=0.0, hi=0.1),
    ),
)

BASELINE = Table(
    "synthesis.baseline",
    "Hand-picked gains (e.g. the paper's) reported beside the design (every layout): true H2, "
    "stability and, with a head vehicle, string stability; an unstable one is reported.",
    _SYN,
    (
        Key("name", "string", "Its label.", "baseline"),
        Key("semantics", "string", "How the gain enters the command.",
            Derived("[synthesis].semantics"), choices=_SEM),
        Key("gains", "table", "State name -> gain; missing states 0. Platoon / ring: one "
            "table per CAV input, gains = { u_3 = { s_3 = ..., v_2 = ... } }.", REQUIRED),
    ),
)

AS_RUN = Table(
    "synthesis.as_run",
    "Design the loop as it runs (structured, string_stable; not fd_lcc, not a ring; an open "
    "platoon: fixed equilibrium, weight 0): estimate, sample-and-hold, latency, filter.",
    _SYN,
    (
        Key("equilibrium", "string", "The controller's equilibrium.", "fixed",
            choices=("fixed", "estimated")),
        Key("equilibrium_tau", "number", 'Time constant of the estimate (only with '
            '"estimated").', 1.0, lo=0.0, lo_open=True, unit="s"),
        Key("sample_time", "number", "Controller period; absent: every simulator step dt.",
            None, lo=0.0, lo_open=True, unit="s"),
        Key("dt", "number", "Simulator step.", 0.01, lo=0.0, lo_open=True, unit="s"),
        Key("latency", "number", "V2V latency of the string check (a multiple of the period).",
            0.0, lo=0.0, unit="s"),
        Key("measurement_filter", "number", "Measurement low-pass time constant (0: off).", 0.0,
            lo=0.0, unit="s"),
        Key("margin", "number", "Relative as-run string-stability margin of accepted steps.",
            1e-3, lo=0.0, hi=0.5),
        Key("weight", "number", "Trade-off weight on the as-run amplification.", 0.0, lo=0.0),
        Key("polish_steps", "integer", "As-run-string-stable polishing iterations.", 200, lo=0,
            hi=100000),
    ),
)

ANALYSIS = Table(
    "analysis",
    "The frequency grid and outputs of analyze.",
    ("analyze",),
    (
        Key("outputs", "any", "A non-empty list of state names whose head -> output responses "
            "are analysed; absent: the defaults of analyze.", None),
        Key("method", "string", "Peak |Gamma| on a grid or by the Hamiltonian test.", "grid",
            choices=("grid", "hamiltonian")),
        Key("omega_min", "number", "Lowest frequency.", 1e-3, lo=0.0, lo_open=True,
            unit=_OMEGA),
        Key("omega_max", "number", "Highest frequency.", 10.0, lo=Derived("omega_min"),
            lo_open=True, unit=_OMEGA),
        Key("points", "integer", "Grid points.", 400, lo=2, hi=100_000),
    ),
)

CASES = Table(
    "cases.NAME",
    "A named static gain (eq. 23) analyze studies.",
    ("analyze",),
    (
        Key("semantics", "string", "How the gain enters the command.", "added", choices=_SEM),
        Key("gains", "table", "State name -> gain; missing states 0. Platoon / ring: one "
            "table per CAV input, [cases.NAME.gains.u_3] with s_i / v_i gains.", {}),
        Key("label", "string", "Label in tables and figures.", Derived("NAME")),
    ),
)

GAIN_TABLE = Table(
    "controllers.NAME.gains",
    "State name -> gain (also [synthesis.baseline.gains], [cases.NAME.gains], "
    "[maps.NAME.gains]); the names are those of the model's state: vehicle i of the layout "
    "(one CAV: counted from the CAV, 0; platoon / ring: positions from the head).",
    ("simulate", "sweep", "run", "synthesize", "analyze", "regions"),
    any_key=Key("STATE", "number", "Gain on s_i (spacing error), v_i (velocity error) or "
                "-p_0 (FD-LCC position); above 100 per unit is a warning (also in a gains "
                "file).", 0.0, lo=-GAIN_MAX, hi=GAIN_MAX, unit="1/s² or 1/s"),
)

REGIONS = Table(
    "regions",
    "Grid and frequency defaults of every [maps.NAME].",
    ("regions",),
    (
        Key("mu", "number list", "Range of the map's spacing gain mu.", [-10.0, 10.0],
            length=2, unit="1/s²"),
        Key("k", "number list", "Range of the map's velocity gain k.", [-10.0, 10.0], length=2,
            unit="1/s"),
        Key("step", "number", "Grid step of both axes (--step overrides).", 0.02, lo=0.0,
            lo_open=True),
        Key("omega_min", "number", "Lowest frequency of the string-stability check.", 1e-3,
            lo=0.0, lo_open=True, unit=_OMEGA),
        Key("omega_max", "number", "Highest frequency.", 1e2, lo=Derived("omega_min"),
            lo_open=True, unit=_OMEGA),
        Key("per_decade", "integer", "Log-spaced frequencies per decade.", 200, lo=10,
            hi=100_000),
        Key("dense_min", "number", "Start of the dense band.", 0.03, lo=0.0, lo_open=True,
            unit=_OMEGA),
        Key("dense_max", "number", "End of the dense band.", 10.0, lo=Derived("dense_min"),
            lo_open=True, unit=_OMEGA),
        Key("dense_per_decade", "integer", "Frequencies per decade in the dense band.", 3000,
            lo=0, hi=100_000),
    ),
)

MAPS = Table(
    "maps.NAME",
    "A (mu, k) stability map of one HDV's gains (Figs. 7, 8); on an open platoon, of one "
    "CAV's gains on an HDV of its segment, the other CAVs' gains fixed.",
    ("regions",),
    (
        Key("vehicle", "integer", "The HDV whose gains are the axes (an index of the system, "
            "not 0; platoon: a position between the CAV's neighbouring CAVs).", REQUIRED),
        Key("cav", "integer", "Platoon only: the position of the CAV whose gains vary "
            "(default: the platoon's only CAV).", None),
        Key("gains", "table", "The other gains, fixed; not the map's own s_i, v_i. Platoon: "
            "one table per CAV input, [maps.NAME.gains.u_5] with s_i / v_i gains, none that "
            "crosses into another CAV's segment.", {}),
        Key("semantics", "string", "How the gain enters the command.", "added", choices=_SEM),
        Key("baseline", "string", "Another map drawn as this one's reference.", None),
        Key("title", "string", "Figure title.", Derived("NAME")),
        Key("mu", "number list", "This map's mu range.", Derived("[regions].mu"), length=2,
            unit="1/s²"),
        Key("k", "number list", "This map's k range.", Derived("[regions].k"), length=2,
            unit="1/s"),
        Key("step", "number", "This map's grid step.", Derived("[regions].step"), lo=0.0,
            lo_open=True),
    ),
)

TABLES = (SYNTHESIS, WEIGHTS, SPARSITY, STRING, BASELINE, AS_RUN, PATTERNS, ROBUST, GAIN_TABLE,
          ANALYSIS, CASES, REGIONS, MAPS)  # fmt: skip
