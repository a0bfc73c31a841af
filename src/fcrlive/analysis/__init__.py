"""FCR analysis: the paper's experiments, the requirement checks and the identification pipeline.

Entry points for the daemon and the Monte Carlo (pure, no I/O)::

    from fcrlive.analysis.identify import identify_signals, identify_full
    report = identify_signals(signals, rated_mw=300.0, kd=0.0, plant=None, method="auto")
    report.to_json_dict()            # the payload of `fcrlive identify --json` (docs/identify.md)

Modules: experiments (Z_cu/Z_ca, Z_ur, Z_u, sine test), assess (droop, peaks, local and TSO checks),
report (pydantic model + text summary), identify (method choice and pipeline), tso_checks, local,
sine_fit, plots. Submodules are imported on use (matplotlib and scipy.optimize are not free).
"""
