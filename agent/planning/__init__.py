"""Planning: threats, via-points, encounters, reference paths, MPC, ORCA, the controller (pure)."""
