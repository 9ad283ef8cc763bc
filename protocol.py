"""The wire protocol shared by the world, the robots and the orchestrator.

Every Zenoh key expression and every message schema lives here and nowhere else.
"""
