"""Identification from measured data: fit the hybrid model, analyse its residual, trace the
residual to a physical effect the model lacks, and report the error before and after.

Modules: ``data`` (trials from CSV files and bags), ``simulate`` (compiled simulators driven by
the measured switching or by the model's own), ``candidates`` (the library of effects),
``fit`` (coast-down friction, multiple-shooting least squares, uncertainty, identifiability),
``residual`` (Ljung-style diagnostics and signatures), ``select`` (effect search with
held-out validation), ``identifiability`` (what a data set determines), ``synthetic``
(recordings from the plant simulator).  A ``report`` module (Markdown, PNG, report.json) is
still to come.
"""
