"""GenRL as an rl-zoo3 algorithm (the ``zoo`` extra): ``python -m sb3_genrl.zoo train --algo genrl --env ...``."""
