"""The baselines of paper section 6.1.5: PPO with behaviour cloning, SAC with and without a prefilled replay buffer,
SAC with hindsight experience replay, and stock algorithms on a generator's latent space."""

# The baselines of ``genrl baseline`` and the study: the feedback baselines with the demonstrations, and stock
# algorithms on a generator's latent space. The one list the CLI, the study and the comparison use.
FEEDBACK_BASELINES = ("ppo", "sac", "sac-no-prefill", "sac-her")
LATENT_BASELINES = ("latent-ppo", "latent-sac", "latent-trpo")
OFF_POLICY_BASELINES = ("sac", "sac-no-prefill", "sac-her")  # checkpointed during training (baselines.checkpoint)
BASELINES = FEEDBACK_BASELINES + LATENT_BASELINES
