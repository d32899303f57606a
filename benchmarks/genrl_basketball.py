"""How close GenRL gets on basketball, and after how many episodes: mean final distance of the deterministic policy.

Makes basketball demonstrations (or reads ``--data``), trains a beta-VAE on them (or reads ``--generator``),
measures the generator's best reachable distance to 300 held-out baskets, then trains GenRL with several seeds (see
``benchmarks/genrl_benchmark.py``). Prints a table, writes JSON and a plot of distance vs episodes.

    python benchmarks/genrl_basketball.py                  # 4000 demos, VAE1 300 epochs, 3 seeds x 20000 episodes
    python benchmarks/genrl_basketball.py --generator quickstart/vae.pt --seeds 0 1 2 3 4
"""

from __future__ import annotations

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from genrl_benchmark import Setting, main  # noqa: E402

BASKETBALL = Setting(task="basketball", target_m=0.10, unit="m", eval_every=1000)

if __name__ == "__main__":
    main(BASKETBALL, __doc__.splitlines()[0])
