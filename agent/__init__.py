"""The robot: the pure planning core (IFP, eIFP, eIFP-MPC, ORCA) and, in `agent.node`, its process.

Importing this package is cheap; the planner modules import numpy/scipy/osqp themselves.
"""
