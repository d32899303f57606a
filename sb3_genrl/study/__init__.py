"""The paper's study at a chosen scale (section 6): ``run_study`` and ``genrl study``."""

from sb3_genrl.study.runner import MODELS, run_study
from sb3_genrl.study.scales import SCALES, StudyScale

__all__ = ["MODELS", "SCALES", "StudyScale", "run_study"]
