"""The orchestrator: setups and scenario families, distributed and lockstep runs, metrics,
plots and reports, behind the `orchestrator` console script (`orchestrator.cli`).
"""
