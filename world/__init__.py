"""The world: ground-truth unicycle dynamics, contacts and arrival (`world.dynamics`, pure),
scenario files (`world.scenario`), and, in `world.node`, the simulation process over Zenoh.
"""
