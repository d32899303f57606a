"""PPO with behaviour cloning and SAC with a prefilled replay buffer (paper section 6.1.5)."""
