"""Simulation: world dynamics, injected link faults and the one lockstep loop (pure)."""
