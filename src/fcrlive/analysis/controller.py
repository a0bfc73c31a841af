"""The governor's digital controller as Z_cu needs it: c/ε, exact or identified and validated.

Z_cu (analysis.experiments.zcu) needs C = c/ε, the controller with its droop loop closed, to turn the
loop model's G_jp into G_p = G_jp C / G_J (paper eq. 19). The paper's plant has a forward-Euler PI with
the droop in the integral channel; real governors (and the validation zoo, fcrlive.sim.zoo) also have
backward-Euler and Tustin integrals, derivative action, the droop around the whole controller, fed back
from the gate or from the demand. This module models all of them as one linear difference equation at the
controller rate,

    A(q⁻¹) c[n] = B_e(q⁻¹) ε[n] − B_x(q⁻¹) x[n] (+ constant),

x the gate position a (droop from the gate) or absent (droop from the demand c: then it is part of A).
With the gate, c/ε = (B_e/A)/(1 + (B_x/A) G_s), G_s = a/c (the servo, fitted by Z_ca); without,
c/ε = B_e/A. Evaluated at z = e^{jωT} these are exact for a digital controller, whatever its
discretisation (the continuous Kp (1 + 1/(Ti s)) of the first version was a forward-Euler approximation
and could not express a PID at all: those plants raised "could not identify a PI controller").

- From a plant description (:func:`from_plant`): the exact G_c(z), K_I(z) of
  :mod:`fcrlive.plant.transfer` (every integral method, PID, both placements and droop signals).
- From the log (:func:`identify`): every governor structure fcrlive.plant.params.Governor spans (PI/PID,
  forward/backward Euler/Tustin integral, droop in the integral channel or around the controller, from the
  gate or the demand) fitted by least squares, the smallest BIC wins. A digital controller's equation holds
  EXACTLY at its own rate, up to the columns' rounding: the fit is validated by its relative residual (rms
  of the residual over the rms of Δc) being below :data:`MAX_REL_RESIDUAL`. Logged below the controller
  rate it does not hold (the controller acted on samples the log does not have), and the identified
  controller is then refused (:class:`ControllerFitError`) instead of biasing every quantity of Z_cu.
  Measured on the zoo (10-min excited records, every plant): ideal logs fit to 1e-12 (7e-7 for a PID,
  whose derivative filter constant is searched), 0.1 % meter noise with 3-decimal columns 0.7e-3 to
  2.1e-3, all with c/ε within 0.01 % of the truth; logs at half the controller rate 0.017-0.12, except
  the slow PIs (D: 100 Hz, Ti = 7 s; E: 25 Hz, from the demand) at 0.0073-0.0083, under the 1 % cap,
  whose droop came out 0.2-0.7 pp off (Z_cu then published it with ±0.03 pp). So the residual must also
  be what the columns' rounding explains (:func:`rounding_residual`, at most :data:`ROUNDING_RATIO` ×):
  at the controller rate the two agree to 1 % on every zoo plant (ratio 0.99-1.01), at half of it D and
  E stand at 4.0-6.4×.

The gate is an exact function of c (the servo), so the split of the equation into its ε and gate parts is
not unique; c/ε with the servo is. The identified equation is therefore kept as fitted, and the Kp, Ti,
droop reported are those of the structure that won (for the report only).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.signal as sps
from scipy.optimize import minimize_scalar

from fcrlive.errors import DataError
from fcrlive.ident import FreqResp

MAX_REL_RESIDUAL = 0.01
"""Largest relative residual of an identified controller's difference equation (module docstring)."""
MAX_SAMPLES = 60_000
"""At most this many samples of the longest segment enter the least squares (the equation is exact; more
only costs time)."""


class ControllerFitError(DataError):
    """The controller's difference equation does not fit the log (the reason is the message)."""


def _ev(coef: np.ndarray, zinv: np.ndarray) -> np.ndarray:
    """Σ coef[i] z⁻ⁱ at the given z⁻¹."""
    return np.polyval(np.asarray(coef, float)[::-1], zinv)


@dataclass(frozen=True, eq=False)
class DigitalController:
    """A(q⁻¹) c = B_e(q⁻¹) ε − B_x(q⁻¹) x at sample time ``Ts`` (module docstring); coefficients in
    ascending powers of q⁻¹. ``b_x`` None: no gate term (droop from the demand, or folded into A)."""

    Ts: float
    a: np.ndarray
    b_e: np.ndarray
    b_x: np.ndarray | None
    rel_residual: float = 0.0
    structure: str = ""

    def _zinv(self, omega) -> np.ndarray:
        return np.exp(-1j * np.asarray(omega, float) * self.Ts)

    def K_e(self, omega) -> np.ndarray:
        """c/ε with the droop loop open [pu/pu]."""
        zi = self._zinv(omega)
        return _ev(self.b_e, zi) / _ev(self.a, zi)

    def K_x(self, omega) -> np.ndarray:
        """c/(−x) with the droop loop open (0 without a gate term)."""
        zi = self._zinv(omega)
        if self.b_x is None:
            return np.zeros_like(zi)
        return _ev(self.b_x, zi) / _ev(self.a, zi)

    def C(self, omega, G_s: FreqResp | None = None) -> FreqResp:
        """c/ε with the droop loop closed: K_e/(1 + K_x G_s) (G_s = a/c; needed with a gate term)."""
        w = np.atleast_1d(np.asarray(omega, float))
        K_e = FreqResp.known(w, self.K_e(w))
        if self.b_x is None:
            return K_e
        if G_s is None:
            raise ValueError("a controller with droop from the gate needs G_s")
        return K_e / (1.0 + FreqResp.known(w, self.K_x(w)) * G_s)


def from_plant(gov, servo_tg: float | None = None) -> DigitalController | None:
    """The exact digital controller of a plant description's digital governor (None for an analogue one).
    ``gov``: fcrlive.plant.params.Governor (its Tc, integral method, Td, droop placement and signal)."""
    if not getattr(gov, "digital", True):
        return None
    from fcrlive.plant.transfer import governor_z

    (nc, dc), (nr, dr) = governor_z(gov)
    # G_c = nc/dc and K_ρ = nr/dr share the denominator (transfer._governor_blocks); polynomials in z,
    # padded to one length they are the same ratios in ascending powers of z⁻¹.
    n = max(len(nc), len(dc), len(nr), len(dr))
    pad = lambda p: np.concatenate((np.zeros(n - len(p)), np.asarray(p, float)))  # noqa: E731
    a, be, bx = pad(dc), pad(nc), gov.droop * pad(nr)
    if gov.droop_signal == "gate":
        return DigitalController(gov.Tc, a, be, bx, 0.0, "plant description")
    # droop from the demand c: A c = B_e ε − B_x c  →  (A + B_x) c = B_e ε
    return DigitalController(gov.Tc, a + bx, be, None, 0.0, "plant description")


@dataclass(frozen=True, eq=False)
class IdentifiedController:
    """The governor structure and parameters that fit the log best, with its exact difference equation."""

    governor: object
    """fcrlive.plant.params.Governor with Kp, Ti, droop, Tc = the log's sample time, the integral method,
    Td/Tdf, placement and droop signal that fit."""
    digital: DigitalController
    rel_residual: float
    structure: str
    alternatives: dict
    """Relative residual of every structure tried (inf: not a governor: non-positive Kp, Ki or droop)."""


def _fit_structure(e, x, c, Ts, placement, method, a_d, with_x: bool):
    """Least squares of c on the structure's regressors in level form (module docstring):
    c[n] = Kp w_p[n] + k Σ w̃_i + D[n] + c₀ + trend, w_p = e (− ρ x, classic), w_i = e − ρ x,
    w̃ = α w[n] + (1 − α) w[n−1], D = b/(1 − a_d q⁻¹) Δw_p. The level form keeps the integral's slow
    content, the part the droop and Ti live in, far above the columns' rounding (the differenced form
    drowned it: ρ 14 % off at 0.1 % noise). Returns (rss, theta, n)."""
    cols = _columns(e, x, placement, method, a_d, with_x)
    if a_d is not None:
        # the derivative's unknown initial state decays as a_d^n (seconds; without it a PID never fit exactly)
        cols["d0"] = a_d ** np.arange(len(e) - 1, dtype=float)
    y = c[1:]
    # the constant and the trend: the initial integral and the integral of the droop signal's operating
    # point ρ x₀ (x is absolute, the controller integrates its deviation)
    X = np.column_stack([*cols.values(), np.ones(len(y)), np.arange(len(y), dtype=float)])
    sc = np.maximum(np.sqrt(np.mean(X**2, axis=0)), 1e-300)
    th, *_ = np.linalg.lstsq(X / sc, y, rcond=None)
    th = th / sc
    res = y - X @ th
    return float(res @ res), dict(zip([*cols, "const", "trend"], th)), len(y)


def _columns(e, x, placement, method, a_d, with_x: bool) -> dict[str, np.ndarray]:
    """The regressors of :func:`_fit_structure` built from ε and the droop signal x (samples 1..N−1)."""
    al = {"forward": 0.0, "backward": 1.0, "tustin": 0.5}[method]
    sl = slice(1, None)

    def integ(v):
        return np.cumsum(al * v[1:] + (1 - al) * v[:-1])

    cols = {"Kp": e[sl], "k": integ(e)}
    if with_x:
        cols["k_rho"] = -integ(x)
        if placement == "classic":
            cols["Kp_rho"] = -x[sl]
    if a_d is not None:
        filt = lambda v: sps.lfilter([1.0], [1.0, -a_d], np.diff(v))  # noqa: E731
        cols["b"] = filt(e)
        if with_x and placement == "classic":
            cols["b_rho"] = -filt(x)
    return cols


def rounding_residual(e, x, c, th: dict, placement: str, method: str, a_d, x_is_c: bool) -> float:
    """The relative residual (rms over rms Δc) that the columns' rounding alone leaves in the fitted
    equation ``th``: uniform rounding errors of each column's quantum (its smallest step) pushed through
    the same regressors, the constant and trend projected out. A fixed generator: the same log gives the
    same figure.

    Why: a digital controller's equation holds exactly at its own rate, so there its residual IS the
    rounding's (measured on the zoo's 30-min excited logs at the controller rate, 8 plants × 2 seeds: the
    ratio residual / this figure 0.99-1.01). Logged below the controller rate it does not hold, but a slow
    PI (the zoo's D, 100 Hz, Ti = 7 s) logged at half its rate still fitted with 0.73 % of Δc, under the
    1 % of :data:`MAX_REL_RESIDUAL`, with the droop 0.2-0.7 pp off and Z_cu's droop interval ±0.03 pp
    around it; its ratio was 4.0-5.8. The test loses power as the rounding grows: with ε rounded to 1 mHz
    (2e-5 pu) the controller-rate logs still fit at their rounding (A, B, D, E, F, paper plant: accepted),
    the half-rate D and E at 1.6-1.7× (refused, near the limit)."""
    from fcrlive.signals import _resolution

    rng = np.random.default_rng(0)
    q_e, q_c = _resolution(e), _resolution(c)
    d_e = rng.uniform(-0.5, 0.5, len(e)) * q_e
    d_c = rng.uniform(-0.5, 0.5, len(c)) * q_c
    d_x = d_c if x_is_c else rng.uniform(-0.5, 0.5, len(x)) * _resolution(x)
    cols = _columns(d_e, d_x, placement, method, a_d, True)
    r = d_c[1:] - sum(th[k] * v for k, v in cols.items())
    n = np.arange(len(r), dtype=float)
    A = np.column_stack((np.ones_like(n), n / max(len(r), 1)))
    r = r - A @ np.linalg.lstsq(A, r, rcond=None)[0]
    scale = float(np.sqrt(np.mean(np.diff(np.asarray(c, float)) ** 2)))
    return float(np.sqrt(np.mean(r**2)) / scale) if scale > 0 else float("inf")


ROUNDING_RATIO = 1.5
"""An identified controller's relative residual may exceed what the columns' rounding explains
(:func:`rounding_residual`) by at most this factor, plus :data:`REL_EXACT` (module docstring)."""
REL_EXACT = 1e-5
"""Relative residual any exact fit may leave beyond the rounding (columns logged as floats, a governor
computing in single precision)."""


DERIVATIVE_TDF_S = tuple(np.geomspace(0.01, 3.0, 16))
DERIVATIVE_GRID_RATIO = float((3.0 / 0.01) ** (1 / 15))
PID_SEARCH_SAMPLES = 12_000
"""Samples the derivative filter constant is searched on (the final fit uses all)."""
PI_GOOD_ENOUGH = 0.005
"""A PI structure fitting within this relative residual is not tried with derivative action (speed: the PID
search is 30 least squares per structure; PI governors at their own rate with 3-decimal columns fit within
1e-3 to 2.1e-3 on the zoo, PID governors fitted by a PI leave > 0.02)."""
REL_FLOOR = 1e-6
"""Relative residual below which fits count as exact (BIC of :func:`identify`)."""
"""Candidate derivative filter time constants Tdf [s] of the PID structures (grid; :func:`identify`)."""


def identify(
    epsilon: np.ndarray, c: np.ndarray, gate: np.ndarray | None, Ts: float, *, where: str | None = None
) -> IdentifiedController:
    """The governor's structure and parameters from logged ε, c (and the gate a) at sample time ``Ts``.

    Every structure of the family fcrlive.plant.params.Governor spans (droop from the gate or the demand,
    integral or classic placement, forward/backward Euler or Tustin integral, PI or PID with a grid of
    derivative filter constants, searched only when no PI fits within :data:`PI_GOOD_ENOUGH`) is a least-
    squares fit of c[n] in level form (:func:`_fit_structure`), linear in (Kp, Kp ρ, Kp Tc/Ti, Kp Tc ρ/Ti,
    the derivative gains); among those with positive Kp, Ki and droop the smallest BIC wins (residual
    floored at :data:`REL_FLOOR`, ties within 1 to the earlier, simpler structure). The fitted equation
    itself (:func:`_equation`) is what Z_cu uses. Validated by the relative residual (rms residual / rms Δc)
    ≤ :data:`MAX_REL_RESIDUAL`: a digital controller logged at its own rate fits to the columns' rounding;
    otherwise :class:`ControllerFitError` says the controller model does not fit, with the residual.
    """
    from fcrlive.plant.params import Governor

    e = np.asarray(epsilon, float)[:MAX_SAMPLES]
    cc = np.asarray(c, float)[:MAX_SAMPLES]
    if len(cc) < 200:
        raise ControllerFitError("too few samples to identify the controller", where=where)
    dc = np.diff(cc)
    scale2 = float(np.mean(dc**2))
    if not scale2 > 0:
        raise ControllerFitError("ContOutSig does not change: the controller cannot be identified",
                                 where=where)
    signals = [("gate", np.asarray(gate, float)[:MAX_SAMPLES])] if gate is not None else []
    signals.append(("demand", cc))
    alts: dict[str, float] = {}
    cands = []

    def fit(sig_name, x, placement, method, tdf, n_max=None):
        a_d = None if tdf is None else tdf / (tdf + Ts)
        sl = slice(None, n_max)
        rss, th, n = _fit_structure(e[sl], x[sl], cc[sl], Ts, placement, method, a_d, True)
        rel = float(np.sqrt(rss / n / scale2))
        ok = th["Kp"] > 1e-6 and th["k"] > 0 and th["k_rho"] > 0 and (tdf is None or th["b"] > 0)
        # parameters: Kp, k, kρ, constant, trend (+ Kp ρ classic) (+ b, Tdf, D₀; + b ρ classic)
        p = 5 + (placement == "classic") + (0 if tdf is None else 3 + (placement == "classic"))
        # BIC on the residual floored at REL_FLOOR: exact fits (an ideal log) tie, and the simplest wins
        bic = n * np.log(max(rel, REL_FLOOR) ** 2) + p * np.log(n)
        return rel, ok, bic, th

    # droop from the demand around the whole controller solves c = Kp (e − ρ c) + I: the same difference
    # equation as the integral placement with Kp/(1 + Kp ρ) etc., hence the same c/ε; fitted once
    structures = [(sig_name, x, placement, method) for sig_name, x in signals
                  for placement in (("integral", "classic") if sig_name == "gate" else ("integral",))
                  for method in ("forward", "backward", "tustin")]
    for sig_name, x, placement, method in structures:
        key0 = f"{placement}/{sig_name}/{method}"
        rel, ok, bic, th = fit(sig_name, x, placement, method, None)
        alts[key0] = rel if ok else float("inf")
        if ok:
            cands.append((bic, rel, key0, sig_name, placement, method, None, th))
    if min((c[1] for c in cands), default=np.inf) > PI_GOOD_ENOUGH:
        for sig_name, x, placement, method in structures:
            # PID: a grid of derivative filter constants on the first PID_SEARCH_SAMPLES, the best refined,
            # then fitted on everything
            def f(t, sig_name=sig_name, x=x, placement=placement, method=method):
                return fit(sig_name, x, placement, method, t, PID_SEARCH_SAMPLES)

            def objective(r):
                # where the gate is an exact function of c (an ideal log) every Tdf fits to rounding with
                # its own split of the gate terms: the floor leaves the choice to the split's consistency
                return max(r[0], REL_FLOOR) + REL_FLOOR * _rho_inconsistency(r[3])

            grid = [(f(t), t) for t in DERIVATIVE_TDF_S]
            grid = [(r, t) for r, t in grid if r[1]]
            if not grid:
                continue
            tdf = min(grid, key=lambda g: objective(g[0]))[1]
            lo, hi = np.log(tdf / DERIVATIVE_GRID_RATIO), np.log(tdf * DERIVATIVE_GRID_RATIO)
            opt = minimize_scalar(lambda lt, f=f: objective(f(float(np.exp(lt)))), bounds=(lo, hi),
                                  method="bounded", options={"xatol": 1e-4})
            tdf = float(np.exp(opt.x))
            rel, ok, bic, th = fit(sig_name, x, placement, method, tdf)
            if not ok:
                continue
            key = f"{placement}/{sig_name}/{method}/PID Tdf={tdf:.3g} s"
            alts[key] = rel
            cands.append((bic, rel, key, sig_name, placement, method, tdf, th))
    if not cands:
        raise ControllerFitError(
            "controller model does not fit: no governor structure (PI/PID, droop from the gate or the "
            "demand, in the integral channel or around the controller) gave positive Kp, Ki and droop",
            where=where)
    # smallest BIC; ties (within 1) to the earlier, simpler candidate: the choice must not hang on rounding
    best = cands[0]
    for cnd in cands[1:]:
        if cnd[0] < best[0] - 1.0:
            best = cnd
    _, rel, key, sig_name, placement, method, tdf, th = best
    if not rel <= MAX_REL_RESIDUAL:
        raise ControllerFitError(
            f"controller model does not fit: the best structure ({key}) leaves a relative residual of "
            f"{rel:.2g} of Δc (a digital controller logged at its own rate: < {MAX_REL_RESIDUAL:g}); "
            f"the log at {1.0 / Ts:.3g} Hz is probably slower than the controller", where=where)
    x_best = dict(signals)[sig_name]
    a_d = None if tdf is None else tdf / (tdf + Ts)
    rel_round = rounding_residual(e, x_best, cc, th, placement, method, a_d, sig_name == "demand")
    if not rel <= ROUNDING_RATIO * rel_round + REL_EXACT:
        raise ControllerFitError(
            f"controller model does not fit: the best structure ({key}) leaves a relative residual of "
            f"{rel:.2g} of Δc, {rel / max(rel_round, 1e-300):.2g}× the {rel_round:.2g} the columns' rounding "
            f"explains (a digital controller logged at its own rate leaves its rounding); the log at "
            f"{1.0 / Ts:.3g} Hz is probably slower than the controller", where=where)
    kp, k = float(th["Kp"]), float(th["k"])
    rho = float(th["k_rho"] / k)
    td = 0.0 if tdf is None else float(th["b"]) * (tdf + Ts) / kp
    gov = Governor(Kp=kp, Ti=kp * Ts / k, droop=rho, Tc=float(Ts), droop_placement=placement,
                   droop_signal=sig_name, integral_method=method, Td=td,
                   Tdf=0.0 if tdf is None else float(tdf))
    return IdentifiedController(gov, _equation(th, Ts, method, tdf, sig_name, rel, key), rel, key, alts)


def _rho_inconsistency(th: dict) -> float:
    """How far the droop's three estimates of a classic PID disagree, relative: ρ = k_ρ/k from the integral,
    Kp ρ/Kp from the proportional and b ρ/b from the derivative term (0 for the integral placement, which
    has k_ρ only).

    Why: on a log without noise (the zoo's ideal logs) the gate is an exact function of c, and every
    derivative filter constant Tdf fits c to rounding (relative residual 1e-13 from 0.005 to 3 s on the
    zoo's PID F) with its own split of the gate terms; the search's minimum was then a rounding coin toss
    (Tdf 0.0132 s or 0.0083 s for the true 0.2 s as the BLAS thread count changed the simulation in the
    16th digit), and with it c/ε through the fitted servo: max|G_1| 0.7686 or 0.7659. Only the true Tdf
    gives one ρ from all three terms."""
    if "Kp_rho" not in th or "b_rho" not in th:
        return 0.0
    rho = th["k_rho"] / th["k"] if th["k"] != 0 else np.inf
    if not np.isfinite(rho) or rho == 0:
        return np.inf
    parts = [th["Kp_rho"] / th["Kp"] if th["Kp"] != 0 else np.inf,
             th["b_rho"] / th["b"] if th["b"] != 0 else np.inf]
    return float(sum(abs(p - rho) for p in parts) / abs(rho))


def _equation(th: dict, Ts: float, method: str, tdf, sig_name: str, rel: float, key: str
              ) -> DigitalController:
    """The fitted level-form equation as A c = B_e ε − B_x x, exactly as fitted (the gate terms Kp ρ and b ρ
    free, not through one ρ: where the gate is an exact function of c their split is not unique, and only
    the equation itself is right on the data)."""
    al = {"forward": 0.0, "backward": 1.0, "tustin": 0.5}[method]
    integ = np.array([al, 1.0 - al])  # (α + (1 − α) q⁻¹)/(1 − q⁻¹)
    one_m = np.array([1.0, -1.0])
    if tdf is None:
        den = one_m
        num = lambda p, k, b: np.polyadd(p * one_m[::-1], k * integ[::-1])[::-1]  # noqa: E731
    else:
        a_d = tdf / (tdf + Ts)
        lag = np.array([1.0, -a_d])
        den = np.convolve(one_m, lag)

        def num(p, k, b):
            return p * den + np.convolve(k * integ, lag) + b * np.convolve(one_m, one_m)
    b_e = num(th["Kp"], th["k"], th.get("b", 0.0))
    b_x = num(th.get("Kp_rho", 0.0), th["k_rho"], th.get("b_rho", 0.0))
    if sig_name == "demand":
        return DigitalController(float(Ts), den + b_x, b_e, None, rel, key)
    return DigitalController(float(Ts), den, b_e, b_x, rel, key)
