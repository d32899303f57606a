"""PPO with behaviour cloning and SAC with a prefilled replay buffer (paper section 6.1.5)."""

# The baselines of ``genrl baseline`` and the study: PPO and SAC on the feedback task with the demonstrations, and
# stock algorithms on a generator's latent space. The one list the CLI, the study and the comparison use.
BASELINES = ("ppo", "sac", "latent-ppo", "latent-sac", "latent-trpo")
