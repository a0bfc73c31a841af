"""Identification engine (work in progress): see the submodules."""

from fcrlive.ident.arx import arx, arxstruc, selstruc
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

__all__ = [
    "EstimationReport", "FreqResp", "IdData", "IdentError", "NonFiniteDataError", "NotExcitingError",
    "OrderError", "PeakGain", "PolyModel", "TooFewSamplesError", "UnstableModelError", "arx", "arxstruc",
    "bj", "oe", "selstruc",
]
