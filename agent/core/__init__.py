"""Core types of the robot and the run: states, plans, configs, scenarios (pure, no I/O)."""
