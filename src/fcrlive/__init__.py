"""fcrlive: live, non-intrusive identification of hydro turbine governors for Nordic FCR.

Units used throughout, unless a docstring says otherwise: per unit (pu) on the unit's own machine
base for power, speed and frequency in pu of f0 (50 Hz), time in seconds, angular frequency in rad/s.
"""

__version__ = "0.1.0"
