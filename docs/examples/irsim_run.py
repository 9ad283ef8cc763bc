"""Run docs/examples/irsim_world.yaml (or the world file given) in IR-SIM with eIFP-MPC.

    python docs/examples/irsim_run.py [WORLD.yaml] [--show]

Without --show it runs headless and prints how the run ended.
"""

from __future__ import annotations

import sys
from pathlib import Path

import irsim

import agent.irsim  # noqa: F401  (registers the IR-SIM behaviour "eifp")


def main(argv: list[str]) -> int:
    show = "--show" in argv
    paths = [a for a in argv if a != "--show"]
    world = paths[0] if paths else str(Path(__file__).with_name("irsim_world.yaml"))
    env = irsim.make(world, display=show, headless=not show, log_level="WARNING")
    for _ in range(1000):
        env.step()
        if show:
            env.render()
        if env.done():
            break
    robots = env.robot_list
    print(f"t = {env.time:.1f} s, arrived {sum(r.arrive for r in robots)}/{len(robots)}, "
          f"collisions {sum(r.collision for r in robots)}")
    env.end(0)
    return 0 if all(r.arrive for r in robots) and not any(r.collision for r in robots) else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
