"""The MPC's quadratic program for any number of CAVs, formulated once with CasADi.

Prediction model: the LCC error model of :mod:`lcc_synth.models.linear` discretised exactly (ZOH) at
the controller's sample time ``Ts``::

    x_{k+1} = Ad x_k + Bd u_k + Hd d_k,          k = 0 .. N-1

with ``d_k`` the predicted head-vehicle velocity error (held constant by default); with
``prediction.delay`` ``x`` is the state augmented with the HDVs' delay states of
:mod:`lcc_synth.mpc.delay` (unweighted, unconstrained). The QP is
condensed: the decision vector is ``z = [u_0 .. u_{N-1}, e_1 .. e_{N*F}]`` (model inputs and one
spacing slack per constrained family and step), and

    min  sum_{k=1}^{N-1} r_k' Q r_k + r_N' P r_N + sum_k w_u a_k^2 + w_j (a_k - a_{k-1})^2
         + rho_1 sum e + rho_2 sum e^2,       r_k = x_k - x_dir d_k
    s.t. a_min <= a_k = K_law x_k + k_h d_k + u_k <= a_max      (hard, total CAV acceleration)
         c_f' x_k + e_{f,k} >= b_{f,k}                           (soft spacing, k = 1..N)
         e >= 0
         |a_k - a_{k-W}| <= J W Ts                              (comfort, k = 0..N-1; option)

The comfort rows (``constraints.jerk_scale > 0``) bound the CAV's 1 s average jerk: with a
command held for ``Ts``, the applied acceleration's change over ``W Ts`` (``W = round(
constraints.jerk_window / Ts)``, 1 s by default) is ``a_k - a_{k-W}``, so the rows are ISO
15622's "average over 1 s" exactly, not a conservative per-sample bound. For ``k < W`` the
earlier value ``a_{k-W}`` is a past applied command (parameter). ``J`` (the bound, per
step) comes with the vectors (:meth:`Formulation.bounds`), so the speed-dependent limit never
touches the matrices; ``J = inf`` disables the rows (the controller does so when the comfort
rows would cost spacing slack: safety first, see :mod:`lcc_synth.mpc.comfort`).

``x_dir d`` is the steady state of the string when the head's velocity error is ``d``: every
velocity error equals ``d`` and every spacing error is ``(alpha2 - alpha3) / alpha1 * d`` (the
linearised equilibrium-spacing curve, ``ds*/dv``). So the cost regulates the string towards
the equilibrium consistent with the PREDICTED head velocity, not towards ``v_eq`` (which lags
the head after a hard brake and would otherwise pull against the safety constraint); with
``d = 0`` it is the plain regulator. FD-LCC (no head input) has ``x_dir = 0``.

``K_law, k_h`` are the CAV's linear HDV law for CF-LCC (whose input is the added ``u_hat``) and
zero otherwise, so ``a_k`` is the CAV's total acceleration; with ``weights.input_on = "model"``
the input and jerk weights apply to ``u_k`` (= ``u_hat``) instead. ``a_{-1}`` is the previous
command. ``P`` solves the discrete algebraic Riccati equation of the same stage cost (with the
cross term ``w_u K_law' u`` when the total acceleration of CF-LCC is weighted); for FD-LCC with a
zero position weight it is solved on the model without the marginal ``-p_0`` state, which no
other state depends on (its row and column of ``P`` are zero).

The condensation is written symbolically in CasADi (MX): every predicted state is an affine
map ``x_k = Xu_k U + Xp_k p`` built by the recursion above, each cost term a residual
``r = Ru U + Rp p`` with weight ``W`` contributing ``2 Ru' W Ru`` to the Hessian and
``2 Ru' W Rp`` to the linear-term map. The model matrices ``theta = (Ad, Bd, Hd, P, x_dir, K_law,
k_h)`` are CasADi symbols too, so the sparsity pattern of the Hessian and of the constraint
matrix is structural and never changes: re-linearising at a new equilibrium only re-evaluates
the numeric values (one call of the CasADi function) and hands them to OSQP with
``update(Px=..., Ax=...)``. The vectors are affine in the step parameter
``p = [x_0, d_0..d_{N-1}, u_{-1}, c_{-1}..c_{-W}]`` (``u_{-1}`` the jerk weight's previous
input, ``c_{-j}`` the applied commands of the comfort rows, absent without them):
``q = Qp p + q0`` and the constraint offset ``Gp p + g0`` (``q0`` holds the l1 slack
penalty), extracted as dense matrices once per linearisation, so a control step is two small
matrix-vector products plus the OSQP update and solve.
(``tests/test_mpc_qp.py`` checks these matrices against the cost and constraints evaluated by
simulating the prediction model in numpy.)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from lcc_synth.errors import ConfigError
from lcc_synth.interrupts import checkpoint
from lcc_synth.models.feedback import Gains, cav_feedback
from lcc_synth.models.hdv import CarFollowingModel
from lcc_synth.models.linear import LCCModel, discretize, model_from_hdv
from lcc_synth.mpc.delay import DelayModel, pad
from lcc_synth.mpc.lag import prediction_extension
from lcc_synth.mpc.settings import MPCSettings
from lcc_synth.resources import single_thread_blas

__all__ = [
    "Family",
    "spacing_families",
    "error_bound",
    "Linearization",
    "QPMatrices",
    "Formulation",
    "state_weights",
    "terminal_cost",
    "riccati",
    "linearize",
    "steady_direction",
]


@dataclass(frozen=True)
class Family:
    """One soft spacing constraint family ``sign (x_k[s] - t_gap * x_k[v]) + e_k >= b_k``
    (k = 1..N; ``b_k`` from the layout's ``spacing_bounds``).

    ``vehicle`` is the paper's index (0 = the CAV's spacing to the vehicle ahead; a position
    of a platoon or ring). ``bound`` is ``"safe"`` (the absolute ``s >= s_min + t_gap v``,
    ``sign`` 1) or one side of the bound on the spacing error from the equilibrium spacing
    (``constraints.spacing = "equilibrium"``): ``"error_min"`` (``s - s*(v_eq) >= s_min``,
    ``sign`` 1) and ``"error_max"`` (``s - s*(v_eq) <= s_min``, ``sign`` -1), both with
    ``t_gap = 0``.
    """

    vehicle: int
    s_index: int
    v_index: int
    t_gap: float
    s_min: float
    bound: str = "safe"

    @property
    def sign(self) -> float:
        """1 for a lower bound, -1 for the upper bound ``error_max``."""
        return -1.0 if self.bound == "error_max" else 1.0


def spacing_families(vehicle: int, s_index: int, v_index: int, constraints) -> list[Family]:
    """The families bounding a CAV's own spacing ahead, as ``constraints.spacing`` selects.

    ``"safe"``: one family, ``s >= s_min + t_gap v`` (absolute). ``"equilibrium"``: the
    DeeP-LCC paper's bound (Wang et al., IEEE T-CST 2023, its simulations: -15 and 20 m)
    ``lo <= s - s*(v_eq) <= hi`` with ``[lo, hi] = constraints.spacing_error``: two families
    on the spacing error alone. The state's spacing error is measured from the layout's
    reference spacing at ``v_eq`` (the HDV model's equilibrium spacing, the OVM's ``s*(v)``),
    so their right-hand sides are the constants of :func:`error_bound` and the bound moves
    with ``v_eq`` through the state.
    """
    c = constraints
    if c.spacing == "safe":
        return [Family(vehicle, s_index, v_index, c.t_gap, c.s_min)]
    lo, hi = c.spacing_error
    return [Family(vehicle, s_index, v_index, 0.0, float(lo), "error_min"),
            Family(vehicle, s_index, v_index, 0.0, float(hi), "error_max")]


def error_bound(fam: Family, margin: float, gap=0.0):
    """Right-hand side ``b`` of a spacing-error family (``error_min`` or ``error_max``).

    ``gap`` is the target spacing minus the spacing the state's zero stands for
    (``s*(v_eq) - (s - x[s])``; 0 when the state's spacing error is measured from the
    target, an array over the horizon for FD-LCC). The row ``sign x[s] + e >= b`` then reads
    ``x[s] - gap >= lo + margin`` or ``x[s] - gap <= hi - margin``.
    """
    if fam.bound == "error_min":
        return fam.s_min + margin + gap
    if fam.bound == "error_max":
        return -(fam.s_min - margin + gap)
    raise ValueError(f"family {fam.bound!r} is not a spacing-error bound")


@dataclass(frozen=True, eq=False)
class Linearization:
    """The discrete prediction model at one equilibrium velocity ``v_lin``."""

    v_lin: float
    model: LCCModel
    Ad: np.ndarray
    Bd: np.ndarray
    Hd: np.ndarray
    P: np.ndarray
    K_law: np.ndarray
    k_h: float
    x_dir: np.ndarray
    delay: DelayModel | None = None  # prediction.delay: the matrices are the augmented ones

    def predict(self, x0: np.ndarray, d: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Predicted states ``(N+1, nx)`` for inputs ``u`` and head errors ``d`` (both ``(N,)``)."""
        X = np.empty((len(u) + 1, x0.size))
        X[0] = x0
        for k in range(len(u)):
            X[k + 1] = self.Ad @ X[k] + self.Bd * u[k] + self.Hd * d[k]
        return X


@dataclass(frozen=True, eq=False)
class QPMatrices:
    """Numeric QP data of one linearisation (``P`` upper triangular, CSC)."""

    P: sp.csc_matrix
    A: sp.csc_matrix
    Qp: np.ndarray
    Gp: np.ndarray
    q0: np.ndarray
    g0: np.ndarray


def state_weights(model: LCCModel, settings: MPCSettings) -> np.ndarray:
    """Diagonal of ``Q``: velocity weight on every ``v_i``, spacing weights on ``s_i``."""
    w = settings.weights
    q = np.empty(model.nx)
    for j, i in enumerate(model.vehicles):
        if i == 0:
            q[2 * j] = w.position if model.kind == "fd_lcc" else w.cav_spacing
        else:
            q[2 * j] = w.spacing
        q[2 * j + 1] = w.velocity
    return q


def terminal_cost(
    model: LCCModel,
    Ad: np.ndarray,
    Bd: np.ndarray,
    q: np.ndarray,
    r: float,
    K_law: np.ndarray | None = None,
):
    """Terminal weight ``P`` from the discrete Riccati equation.

    The stage cost is ``x'diag(q)x + r (K_law x + u)^2`` (``K_law`` = 0 when omitted).

    For FD-LCC with zero weight on ``-p_0`` the position state (eigenvalue 1, observed by no
    other state and unweighted) makes the Riccati equation ill-posed; it is removed, and ``P``
    gets a zero row and column for it.

    Raises
    ------
    ConfigError
        When the Riccati equation has no stabilising solution.
    """
    nz = Ad.shape[0]  # model.nx, or more with delay states
    keep = np.arange(nz)
    if model.kind == "fd_lcc" and q[0] == 0.0:
        keep = keep[1:]
    A_r = Ad[np.ix_(keep, keep)]
    B_r = Bd[keep].reshape(-1, 1)
    Q_r = np.diag(q[keep])
    S_r = None
    if K_law is not None and np.any(K_law != 0.0):
        k = np.asarray(K_law, float)[keep].reshape(-1, 1)
        Q_r = Q_r + r * (k @ k.T)
        S_r = r * k
    P = np.zeros((nz, nz))
    P[np.ix_(keep, keep)] = riccati(A_r, B_r, Q_r, np.array([[r]]), S_r)
    return P


def riccati(A: np.ndarray, B: np.ndarray, Q: np.ndarray, R: np.ndarray,
            S: np.ndarray | None = None) -> np.ndarray:  # fmt: skip
    """The symmetrised stabilising solution of the discrete Riccati equation (SciPy's
    ``solve_discrete_are``) of every layout's terminal cost.

    Raises
    ------
    ConfigError
        ``weights`` when there is no stabilising or no finite solution.
    """
    try:
        P = sla.solve_discrete_are(A, B, Q, R, s=S)
    except (np.linalg.LinAlgError, ValueError) as err:
        raise ConfigError(
            "weights",
            f"the terminal Riccati equation has no stabilising solution ({err}); "
            "give positive velocity and spacing weights",
        ) from None
    if not np.all(np.isfinite(P)):
        raise ConfigError("weights", "the terminal Riccati solution is not finite")
    return 0.5 * (P + P.T)


def linearize(
    kind: str,
    m: int,
    n: int,
    hdv: CarFollowingModel,
    v_lin: float,
    settings: MPCSettings,
) -> Linearization:
    """Linearise the HDV model at ``v_lin`` and build the discrete prediction model."""
    with single_thread_blas():
        return _linearize(kind, m, n, hdv, v_lin, settings)


def _linearize(kind, m, n, hdv, v_lin, settings) -> Linearization:
    model = model_from_hdv(kind, m, n, hdv, v_lin, warn=False)
    Ts = settings.sample_time
    Ad, BH = discretize(model.A, np.hstack([model.B, model.H]), Ts)
    Bd, Hd = BH[:, 0].copy(), BH[:, 1].copy()
    q = state_weights(model, settings)
    if kind == "cf_lcc":
        K_law, k_h = cav_feedback(model, Gains.named({}, "added"))
        K_law = np.asarray(K_law, float)
    else:
        K_law, k_h = np.zeros(model.nx), 0.0
    total = settings.weights.input_on == "total"
    x_dir, dm = steady_direction(model), prediction_extension(model, settings.prediction, Ts)
    if dm is not None:  # delay states (lcc_synth.mpc.delay) or the CAV's lag (mpc.lag)
        Ad, Bd, Hd = dm.Ad, dm.Bd[:, 0], dm.Hd[:, 0]
        q, K_law, x_dir = pad(q, dm.nz), pad(K_law, dm.nz), pad(x_dir, dm.nz)
    P = terminal_cost(model, Ad, Bd, q, settings.weights.input, K_law if total else None)
    return Linearization(float(v_lin), model, Ad, Bd, Hd, P, K_law, float(k_h), x_dir, dm)


def steady_direction(model: LCCModel) -> np.ndarray:
    """``x_dir``: the equilibrium error state per unit head-velocity error (zero for FD-LCC)."""
    x = np.zeros(model.nx)
    if model.kind == "fd_lcc":
        return x
    for j, i in enumerate(model.vehicles):
        c = model.coefficients[i]
        x[2 * j] = (c.alpha2 - c.alpha3) / c.alpha1
        x[2 * j + 1] = 1.0
    return x


#: longest MPC horizon: building the condensed QP grows like N^3 (N = 400: 9 s, 1.4 GiB)
MAX_HORIZON = 500


def formulation_bytes(N: int, nx: int, families: int) -> float:
    """Estimated peak bytes of :class:`Formulation` for horizon ``N``: the CasADi build of the
    condensed QP (measured about ``20 N^3`` bytes) plus the dense Hessian, constraint and
    parameter maps (``8 (N + F N) (nx + 2 N)`` each)."""
    return 20.0 * N**3 + 8.0 * (3 + 2 * families) * N * (nx + 2 * N)


def check_horizon(N: int, nx: int, families: int) -> None:
    """Refuse a horizon above :data:`MAX_HORIZON` or one whose QP cannot fit in memory."""
    from lcc_synth.errors import ConfigError
    from lcc_synth.resources import format_bytes, require_memory

    need = formulation_bytes(N, nx, families)
    if N > MAX_HORIZON:
        raise ConfigError(
            "horizon",
            f"{N} is above the limit {MAX_HORIZON} (the condensed QP would take about "
            f"{format_bytes(need)} to build, growing like N^3); use a longer sample_time",
        )
    require_memory("horizon", need, f"condensed QP, horizon {N}, {nx} states",
                   "shorten the horizon")


def _to_csc(dm) -> sp.csc_matrix:
    s = dm.sparsity()
    colind, row = s.get_ccs()
    data = np.array(dm.nonzeros(), dtype=float)
    return sp.csc_matrix((data, np.asarray(row), np.asarray(colind)), shape=dm.shape)


class Formulation:
    """The symbolic condensed QP of any number of CAVs (built once; :meth:`matrices` per
    linearisation).

    One class serves the single-CAV MPC (``nu = 1``, the paper's error state; CF-LCC couples
    the HDV law into the CAV's total acceleration) and the joint MPC of every CAV of a
    platoon or ring (``nu`` inputs, :mod:`lcc_synth.mpc.joint_prediction`). Built once per
    controller (about 0.15 s); :meth:`matrices` evaluates it at a linearisation (about 10 ms
    for n = 10, N = 50). Measured when the two former classes became this one: with one
    input it gives the single-CAV class's QP data and with several the joint class's, bit for
    bit (values, CSC patterns, step parameters, bounds and warm-start shifts, on 160
    combinations of kind, comfort rows, jerk weight, constraints behind, delay states,
    ``input_on``, open and ring layouts).

    Parameters
    ----------
    kind : str
        Model kind; ``"cf_lcc"`` adds the HDV law to the input constraint (``nu = 1`` only).
    nx : int
        Number of states.
    settings : MPCSettings
    q : numpy.ndarray
        Diagonal of the stage weight ``Q``.
    families : list of Family
        Soft spacing constraints.
    nu : int
        Number of inputs (CAVs); ``z`` holds ``u_k`` step-major, ``nu`` entries per step.
    """

    def __init__(self, kind: str, nx: int, settings: MPCSettings, q, families: list[Family],
                 nu: int = 1):  # fmt: skip
        import casadi as ca

        cf = kind == "cf_lcc"
        if cf and nu != 1:
            raise ConfigError("system.kind", "cf_lcc has one CAV (one input)")
        self.kind = kind
        self.nx, self.nu = nx, nu
        self.N = N = settings.horizon
        self.n_input = NU = N * nu
        self.families = list(families)
        F = len(self.families)
        FN = F * N
        self.nz = NU + FN
        c = settings.constraints
        self.W = W = max(1, int(round(c.jerk_window / settings.sample_time))) \
            if c.jerk_scale > 0 else 0
        self.window = W * settings.sample_time
        self.nc = NU + 2 * FN + (NU if W else 0)
        self.n_param = npar = nx + N + nu + W * nu
        o_prev = nx + N  # u_{-1} block; c_{-j} block at o_prev + j nu
        w = settings.weights

        Ad = ca.MX.sym("Ad", nx, nx)
        Bd = ca.MX.sym("Bd", nx, nu)
        Hd = ca.MX.sym("Hd", nx, 1)
        P = ca.MX.sym("P", nx, nx)
        xdir = ca.MX.sym("xdir", nx, 1)
        theta = [Ad, Bd, Hd, P, xdir]
        if cf:
            K = ca.MX.sym("K", 1, nx)
            kh = ca.MX.sym("kh")
            theta += [K, kh]
        Qd = ca.DM(np.diag(np.asarray(q, dtype=float)))

        def sel(rows: int, cols: int, start: int):
            """``rows x cols`` selector of the ``rows`` entries from ``start``."""
            return ca.DM(ca.Sparsity.triplet(rows, cols, list(range(rows)),
                                             list(range(start, start + rows))), 1.0)

        # x_k = Xu[k] U + Xp[k] p (structural zeros kept sparse)
        Xu = [ca.MX(nx, NU)]
        Xp = [ca.MX(ca.horzcat(ca.DM.eye(nx), ca.DM(nx, npar - nx)))]
        au, ap = [], []  # total CAV accelerations a_k = au[k] U + ap[k] p
        for k in range(N):
            if cf:
                au.append(K @ Xu[k] + sel(1, NU, k))
                ap.append(K @ Xp[k] + kh * sel(1, npar, nx + k))
            else:
                au.append(ca.MX(sel(nu, NU, k * nu)))
                ap.append(ca.MX(nu, npar))
            Xu.append(Ad @ Xu[k] + Bd @ sel(nu, NU, k * nu))
            Xp.append(Ad @ Xp[k] + Hd @ sel(1, npar, nx + k))

        Huu = ca.MX(NU, NU)
        Qp_u = ca.MX(NU, npar)

        def add(Ru, Rp, Wt):
            nonlocal Huu, Qp_u
            WRu = Wt @ Ru
            Huu += 2 * (Ru.T @ WRu)
            Qp_u += 2 * (WRu.T @ Rp)

        # stage and terminal cost on r_k = x_k - x_dir d_k (terminal: d_{N-1})
        for k in range(1, N + 1):
            i = min(k, N - 1)
            add(Xu[k], Xp[k] - xdir @ sel(1, npar, nx + i), Qd if k < N else P)
        # input (total acceleration or model input) and jerk
        if w.input_on == "total" and cf:
            Wu, Wp = ca.vertcat(*au), ca.vertcat(*ap)
        else:
            Wu, Wp = ca.MX(ca.DM.eye(NU)), ca.MX(NU, npar)
        add(Wu, Wp, ca.DM(w.input))
        if w.jerk > 0:
            prev_u = ca.vertcat(ca.MX(nu, NU), Wu[: NU - nu, :])
            prev_p = ca.vertcat(ca.MX(sel(nu, npar, o_prev)), Wp[: NU - nu, :])
            add(Wu - prev_u, Wp - prev_p, ca.DM(w.jerk))

        # Hessian, linear term, constraints
        H = ca.blockcat([[Huu, ca.MX(NU, FN)],
                         [ca.MX(FN, NU), ca.MX(2 * w.slack_quadratic * ca.DM.eye(FN))]])
        Qp = ca.vertcat(Qp_u, ca.MX(FN, npar))
        q0 = ca.vertcat(ca.DM(NU, 1), ca.DM.ones(FN, 1) * w.slack)
        rows_u = [ca.horzcat(ca.vertcat(*au), ca.MX(NU, FN))]
        rows_p = [ca.vertcat(*ap)]
        for f, fam in enumerate(self.families):
            sg = fam.sign
            cfam = ca.DM(ca.Sparsity.triplet(1, nx, [0, 0], [fam.s_index, fam.v_index]),
                         [sg, -sg * fam.t_gap])  # fmt: skip
            slack = ca.DM(ca.Sparsity.triplet(N, FN, list(range(N)),
                                              [f * N + k for k in range(N)]), 1.0)  # fmt: skip
            rows_u.append(ca.horzcat(ca.vertcat(*[cfam @ Xu[k] for k in range(1, N + 1)]), slack))
            rows_p.append(ca.vertcat(*[cfam @ Xp[k] for k in range(1, N + 1)]))
        rows_u.append(ca.horzcat(ca.MX(FN, NU), ca.MX(ca.DM.eye(FN))))
        rows_p.append(ca.MX(FN, npar))
        if W:  # comfort rows a_k - a_{k-W}, a_{k-W} = c_{k-W} (parameter) for k < W
            for k in range(N):
                ru, rp = au[k], ap[k]
                if k >= W:
                    ru, rp = ru - au[k - W], rp - ap[k - W]
                else:
                    rp = rp - sel(nu, npar, o_prev + (W - k) * nu)
                rows_u.append(ca.horzcat(ru, ca.MX(nu, FN)))
                rows_p.append(rp)
        A = ca.vertcat(*rows_u)
        Gp = ca.vertcat(*rows_p)
        g0 = ca.DM(self.nc, 1)
        self._fun = ca.Function(
            "mpc_qp", theta, [ca.triu(H), A, Qp, Gp, ca.MX(q0), ca.MX(g0)]
        )
        checkpoint()  # CasADi's wrappers drop a signal's exception (lcc_synth.interrupts)

    def theta(self, lin) -> list:
        """Numeric arguments of the CasADi function for ``lin``."""
        args = [lin.Ad, lin.Bd, lin.Hd, lin.P, lin.x_dir]
        if self.kind == "cf_lcc":
            args += [lin.K_law.reshape(1, -1), lin.k_h]
        return args

    def matrices(self, lin) -> QPMatrices:
        """Evaluate the QP data at ``lin`` (fixed sparsity pattern, see the module docstring)."""
        H, A, Qp, Gp, q0, g0 = self._fun(*self.theta(lin))
        return QPMatrices(
            _to_csc(H),
            _to_csc(A),
            np.array(Qp),
            np.array(Gp),
            np.array(q0).reshape(-1),
            np.array(g0).reshape(-1),
        )

    @property
    def jerk_rows(self) -> slice:
        """Rows of the comfort constraints (empty without them)."""
        return slice(self.nc - (self.n_input if self.W else 0), self.nc)

    def param(self, x0: np.ndarray, d: np.ndarray, u_prev,
              past: np.ndarray | None = None) -> np.ndarray:
        """The step parameter ``p = [x0, d, u_prev, c_{-1}..c_{-W}]``.

        ``u_prev`` has ``nu`` entries (a float for one input); ``past`` holds the last applied
        commands, newest first, ``(>= W,)`` or ``(>= W, nu)`` (default: all equal to
        ``u_prev``).
        """
        u_prev = np.asarray(u_prev, float).reshape(self.nu)
        if past is None:
            c = np.tile(u_prev, self.W)
        else:
            c = np.asarray(past, float)[: self.W].reshape(-1)
        return np.concatenate([x0, d, u_prev, c])

    def bounds(self, qp: QPMatrices, p: np.ndarray, a_min, a_max, fam_bounds: np.ndarray,
               jerk=np.inf) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(q, l, u)`` of OSQP for parameter ``p``.

        ``a_min``, ``a_max`` and ``jerk`` are per input (scalars broadcast). ``fam_bounds`` is
        ``(F, N)``: the right-hand side ``b_{f,k}`` of every spacing row (``-inf`` disables a
        row). ``jerk`` (m/s^3) bounds the average jerk over the comfort window: ``|a_k -
        a_{k-W}| <= jerk * W * Ts`` (``inf`` disables the rows).
        """
        NU, FN = self.n_input, len(self.families) * self.N
        off = qp.Gp @ p + qp.g0
        if np.ndim(a_min) or np.ndim(a_max):
            key = (tuple(np.broadcast_to(a_min, self.nu)), tuple(np.broadcast_to(a_max, self.nu)))
        else:
            key = (a_min, a_max)
        if getattr(self, "_rows_key", None) != key:  # the rows that do not change per step
            lo_t, hi_t = np.empty(self.nc), np.empty(self.nc)
            lo_t[:NU] = np.tile(np.broadcast_to(np.asarray(a_min, float), self.nu), self.N)
            hi_t[:NU] = np.tile(np.broadcast_to(np.asarray(a_max, float), self.nu), self.N)
            hi_t[NU:NU + FN] = np.inf
            lo_t[NU + FN:], hi_t[NU + FN:] = 0.0, np.inf
            self._rows, self._rows_key = (lo_t, hi_t), key
        lo, hi = self._rows[0].copy(), self._rows[1].copy()
        lo[NU:NU + FN] = np.asarray(fam_bounds, float).reshape(-1)
        if self.W:
            r = self.jerk_rows
            if np.ndim(jerk):
                J = np.tile(np.asarray(jerk, float).reshape(self.nu), self.N) * self.window
            else:
                J = jerk * self.window
            lo[r] = -J
            hi[r] = J
        np.subtract(lo, off, out=lo)
        np.subtract(hi, off, out=hi)
        return qp.Qp @ p + qp.q0, lo, hi

    def shift_indices(self) -> tuple[np.ndarray, np.ndarray]:
        """Index arrays that shift a primal / dual solution by one step (warm start)."""
        N, nu = self.N, self.nu
        step = np.minimum(np.arange(N) + 1, N - 1)
        blk_u = (step[:, None] * nu + np.arange(nu)[None, :]).reshape(-1)
        FN = len(self.families) * N
        fam = np.concatenate([step + f * N for f in range(len(self.families))]) \
            if FN else np.zeros(0, int)
        zi = np.concatenate([blk_u, self.n_input + fam]).astype(int)
        parts = [blk_u, self.n_input + fam, self.n_input + FN + fam]
        if self.W:
            parts.append(self.n_input + 2 * FN + blk_u)
        return zi, np.concatenate(parts).astype(int)
