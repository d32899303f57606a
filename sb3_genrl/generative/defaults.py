"""The paper's generative-model constants (section 6.1.2, appendix B), which every model file may import."""

# Section 6.1.2: latent dimensions N_alpha and the regularisation weights of the grid (paper table 1).
LATENT_DIMS = (2, 3, 6)
BETAS = (0.01, 0.005, 0.001)
INFO_WEIGHTS = (0.1, 1.5, 3.5)
# Section 6.1.2: trajectories of 7 joints (their horizon is the task's, read from the data or the task's spec).
N_JOINTS = 7
# Appendix B: "trained for 5000 epochs with learning rate fixed to 2e-4 using batch size 256"; model selection by the
# squared error between "100 randomly generated trajectories" and held-out test trajectories.
EPOCHS = 5000
LEARNING_RATE = 2e-4
BATCH_SIZE = 256
SELECTION_SAMPLES = 100
# Section 6.1.2: about 40K demonstrations per task (used for benchmark sizes).
N_DEMONSTRATIONS = 40_000

MODEL_KINDS = ("vae", "gan")
