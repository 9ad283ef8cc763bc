"""The world: ground-truth unicycle dynamics, contacts and arrival (`world.sim.dynamics`, pure),
scenario files (`world.scenario_file`), and, in `world.node`, the simulation process over Zenoh.
"""
