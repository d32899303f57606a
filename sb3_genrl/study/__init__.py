"""The paper's study at a chosen scale (section 6): ``run_study`` and ``genrl study``."""

from sb3_genrl.study.runner import MODELS, TASKS, run_study
from sb3_genrl.study.scales import SCALES, StudyScale

__all__ = ["MODELS", "SCALES", "TASKS", "StudyScale", "run_study"]
