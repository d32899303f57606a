"""The baselines of paper section 6.1.5: PPO with behaviour cloning, SAC with and without a prefilled replay buffer,
SAC with hindsight experience replay, and stock algorithms on a generator's latent space."""

FEEDBACK_BASELINES = ("ppo", "sac", "sac-no-prefill", "sac-her")
LATENT_BASELINES = ("latent-ppo", "latent-sac", "latent-trpo")
BASELINES = FEEDBACK_BASELINES + LATENT_BASELINES
