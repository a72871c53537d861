"""Identification from measured data: fit the hybrid model, analyse its residual, trace the
residual to a physical effect the model lacks, and report the error before and after.

Modules: ``data`` (trials from CSV files and bags), ``simulate`` (compiled simulators driven by
the measured switching or by the model's own), ``candidates`` (the library of effects),
``fit`` (coast-down friction, multiple-shooting least squares, uncertainty, identifiability),
``screen`` (score tests of each candidate from the current fit), ``residual`` (Ljung-style
diagnostics and signatures), ``periodic`` and ``actuator`` (sizing what the residual shows
along an angle or per actuator), ``consistency`` (an effect refitted trial by trial and
beside the measuring devices), ``select`` (effect search with held-out validation),
``metrics`` and ``prediction`` (simulation and one-step errors), ``identifiability`` (what a
data set determines), ``report`` and ``plots`` (report.md, report.json, PNG figures and
model.yaml), ``threads`` (the worker threads and BLAS limit the fits share), ``synthetic``
(recordings from the plant simulator).

Importing the package leaves OpenBLAS's kernel choice alone; ``hasel_wheel identify`` and the
identification benchmarks pin it (:mod:`.numerics`).
"""
