"""Experiments: distributed and lockstep runs, sweeps, stress, scale, bench, the compose demo."""
