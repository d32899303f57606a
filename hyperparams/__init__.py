"""The settings files of GenRL and the baselines (``<algo>.yml``, rl-zoo3's format), read by :mod:`sb3_genrl.hyperparams`."""
