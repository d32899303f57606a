"""How close GenRL gets on hockey, and after how many episodes: mean final distance of the deterministic policy.

Makes hockey demonstrations (or reads ``--data``), trains a beta-VAE on them (or reads ``--generator``), measures
the generator's best reachable distance to the held-out goals, then trains GenRL with several seeds (see
``benchmarks/genrl_benchmark.py``). Prints a table, writes JSON and a plot of distance vs episodes.

    python benchmarks/genrl_hockey.py                                  # 4000 demos, VAE1 300 epochs, 3 seeds x 3000 episodes
    python benchmarks/genrl_hockey.py --generator quickstart/vae.pt --seeds 0 1 2 3 4 --episodes 6000
"""

from __future__ import annotations

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from genrl_benchmark import Setting, main  # noqa: E402

HOCKEY = Setting(task="hockey", target_m=0.05, unit="cm")

if __name__ == "__main__":
    main(HOCKEY, __doc__.splitlines()[0])
