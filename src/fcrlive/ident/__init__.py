"""Identification engine: prediction-error ARX, OE and Box-Jenkins with honest uncertainty.

Usage guide (numpy in, frozen dataclasses out; ω always in rad/s, evaluated at z = e^{jωTs})::

    from fcrlive.ident import IdData, arx, bj, oe, two_stage, resid, compare, aic

    data = IdData(y, np.column_stack([u, r]), Ts=0.1, output_name="eps", input_names=("u", "r"))
    data = data.split().detrend("mean")          # cut NaN gaps into experiments, remove means
    data = data.decimate(5)                      # zero-phase anti-aliasing, Ts becomes 0.5 s

    m = arx(data, na=20, nb=20, nk=0)            # MISO least squares (QR), Cov = λ̂(RᵀR)⁻¹
    m = bj(data, nb=2, nc=1, nd=1, nf=2, nk=1)   # prediction error, Gauss-Newton + LM, multi-start
    m = oe(data, 2, 2, 1, ic="estimate",          # initial states + offset estimated (slow poles,
           covariance="sandwich")                 # records not at rest); Newey-West covariance
    m.theta, m.sd, m.report                      # parameters [a, b, c, d, f], sd, how it converged

    G1 = m.freqresp(omega, input="u")            # FreqResp: value, sd_abs, sd_phase, ci95_abs()
    S = m.freqresp(omega, input="r")
    Gp = (1 - S) / G1                            # paper eq. 15; covariance propagated (shared model)
    Gp.max_abs()                                 # peak |G| with its ω and sd
    m.static_gain(input="u")                     # (G(1), sd)

    resid(m, data).passed, compare(m, data).fit_percent, aic(m)

Closed loop: direct ``bj`` is consistent with a delay in the loop and a right noise model; when the
excitation r is measured, ``two_stage`` / ``projection`` are consistent whatever the noise model.
Errors (``NonFiniteDataError``, ``NotExcitingError``, ``TooFewSamplesError``, ``OrderError``,
``UnstableModelError``) name the signal or order at fault. Conventions are MATLAB's: ``nb`` counts
coefficients, ``nk`` leading zeros, θ = [a, b_1..b_nu, c, d, f_1..f_nu].
"""

from fcrlive.ident.arx import StrucTable, arx, arxstruc, selstruc
from fcrlive.ident.closedloop import choose_fir_length, fir_projection, projection, two_stage
from fcrlive.ident.data import IdData
from fcrlive.ident.errors import (
    IdentError,
    NonFiniteDataError,
    NotExcitingError,
    OrderError,
    TooFewSamplesError,
    UnstableModelError,
)
from fcrlive.ident.freqresp import FreqResp, PeakGain
from fcrlive.ident.pem import bj, oe
from fcrlive.ident.poly import EstimationReport, PolyModel
from fcrlive.ident.validation import (
    CompareResult,
    OrderSearchResult,
    ResidResult,
    XResidResult,
    aic,
    arx_order_search,
    bic,
    bj_order_search,
    compare,
    fpe,
    resid,
    xresid,
)

__all__ = [
    "CompareResult", "EstimationReport", "FreqResp", "IdData", "IdentError", "NonFiniteDataError",
    "NotExcitingError", "OrderError", "OrderSearchResult", "PeakGain", "PolyModel", "ResidResult",
    "StrucTable", "TooFewSamplesError", "UnstableModelError", "XResidResult", "aic", "arx",
    "arx_order_search", "arxstruc", "bic", "bj", "bj_order_search", "choose_fir_length", "compare",
    "fir_projection", "fpe", "oe", "projection", "resid", "selstruc", "two_stage", "xresid",
]
