"""The GenRL algorithm (paper section 4): EM policy training over a generator's latent space."""

from sb3_genrl.genrl.genrl import GenRL
from sb3_genrl.genrl.hindsight import HindsightRelabelling
from sb3_genrl.genrl.hindsight_buffer import HindsightRolloutBuffer
from sb3_genrl.genrl.kept_pulls import KeptPulls
from sb3_genrl.genrl.policies import MlpPolicy, MultiInputPolicy
from sb3_genrl.genrl.refits import Refits
from sb3_genrl.genrl.settings import check_genrl_settings

__all__ = [
    "GenRL",
    "HindsightRelabelling",
    "HindsightRolloutBuffer",
    "KeptPulls",
    "MlpPolicy",
    "MultiInputPolicy",
    "Refits",
    "check_genrl_settings",
]
