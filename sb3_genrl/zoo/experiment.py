"""rl-zoo3's ``ExperimentManager`` for GenRL: the generator named in the saved run, and evaluation on tuning goals.

Three things differ from rl-zoo3's own manager, for ``--algo genrl`` only:

- the env wrapper's generator is resolved before any env is made (the task's quickstart generator is made into the
  cache when missing, :mod:`sb3_genrl.zoo.generators`), and the run's ``config.yml`` records its file and content
  digest, so that ``enjoy`` and ``record_video`` play the policy with the generator it was trained with; a
  :class:`~sb3_genrl.genrl.demonstrations.DemonstrationCallback` without a dataset (the Fetch tasks' entries) gets the
  demonstrations that generator was trained on, recorded in ``config.yml`` with their fingerprint;
- every evaluation env (``EvalCallback`` while training, the trials' evaluations with ``-optimize``) draws its goals
  from :data:`~sb3_genrl.hyperparams.TUNING_GOAL_SEED` afresh at each evaluation, the same goals each time and never
  the held-out ones (:data:`~sb3_genrl.hyperparams.EVAL_GOAL_SEED`);
- a study's first trial is the task entry's own settings (when they lie in the sampler's space), so that its best
  trial is never worse on the tuning goals than the settings it would replace.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from typing import Any

import optuna
from rl_zoo3.exp_manager import ExperimentManager
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper

from sb3_genrl.hyperparams import TUNING_GOAL_SEED

WRAPPER = "sb3_genrl.zoo.latent_action"


class TuningGoals(VecEnvWrapper):
    """Each ``reset()`` reseeds the envs, env ``i`` with ``seed + i``: every evaluation plays the same goals. With one
    env the goals of an evaluation of ``n`` episodes are those of
    :func:`sb3_genrl.genrl.train.evaluate_on_goals` with ``goals=n`` and the same seed. With ``seed=None`` (the
    training envs, wrapped alike so that SB3's ``EvalCallback`` sees envs of one type) nothing is reseeded."""

    def __init__(self, venv: VecEnv, seed: int | None = TUNING_GOAL_SEED) -> None:
        super().__init__(venv)
        self.goal_seed = seed

    def reset(self) -> Any:
        if self.goal_seed is not None:
            self.venv.seed(self.goal_seed)
        return self.venv.reset()

    def step_wait(self) -> Any:
        return self.venv.step_wait()


class GenRLExperimentManager(ExperimentManager):
    """rl-zoo3's ``ExperimentManager`` with GenRL's generator, tuning goals and first trial (see the module)."""

    def read_hyperparameters(self) -> tuple[dict[str, Any], dict[str, Any]]:
        hyperparams, saved = super().read_hyperparameters()
        if self.algo == "genrl":
            wrapper = resolved_wrapper(hyperparams.get("env_wrapper"), self.env_name.gym_id, self.device)
            hyperparams["env_wrapper"] = saved["env_wrapper"] = wrapper
            if hyperparams.get("callback") is not None:
                callback = resolved_callback(hyperparams["callback"], wrapper, self.env_name.gym_id)
                hyperparams["callback"] = saved["callback"] = callback
        return hyperparams, saved

    def create_envs(self, n_envs: int, eval_env: bool = False, no_log: bool = False) -> VecEnv:
        env = super().create_envs(n_envs, eval_env=eval_env, no_log=no_log)
        if self.algo != "genrl":
            return env
        return TuningGoals(env, TUNING_GOAL_SEED if eval_env else None)

    def hyperparameters_optimization(self) -> None:
        with self._entry_as_first_trial():
            super().hyperparameters_optimization()

    @contextlib.contextmanager
    def _entry_as_first_trial(self) -> Iterator[None]:
        """rl-zoo3 makes its study inside ``hyperparameters_optimization``: a new study gets the entry's settings
        enqueued as its first trial."""
        from sb3_genrl.zoo.sampler import entry_params

        params = entry_params(self._hyperparams) if self.algo == "genrl" else None
        if params is None:
            yield
            return
        create_study = optuna.create_study

        def create_with_entry(*args: Any, **kwargs: Any) -> optuna.Study:
            study = create_study(*args, **kwargs)
            if not study.trials:
                study.enqueue_trial(params, user_attrs={"settings": "the task's entry in hyperparams/genrl.yml"})
            return study

        optuna.create_study = create_with_entry
        try:
            yield
        finally:
            optuna.create_study = create_study


def resolved_wrapper(env_wrapper: Any, env_id: str, device: Any = "auto") -> Any:
    """The entry's ``env_wrapper`` with the latent-action wrapper's generator file and digest filled in (the task's
    quickstart generator made into the cache when the entry names none and it is missing)."""
    from sb3_genrl.genrl.generator_files import generator_digest
    from sb3_genrl.zoo.generators import build_default_generator, default_generator
    from sb3_genrl.zoo.wrapper import load_generator, resolve_generator

    wrappers = env_wrapper if isinstance(env_wrapper, list) else [env_wrapper]
    resolved = []
    for wrapper in wrappers:
        name, kwargs = next(iter(wrapper.items())) if isinstance(wrapper, dict) else (wrapper, {})
        if name != WRAPPER:
            resolved.append(wrapper)
            continue
        kwargs = dict(kwargs or {})
        if kwargs.get("generator") is None and not default_generator(env_id).is_file():
            build_default_generator(env_id, device=str(device))
        path = resolve_generator(kwargs.get("generator"), env_id)
        kwargs.update(generator=str(path.resolve()), generator_sha256=generator_digest(load_generator(path)))
        resolved.append({name: kwargs})
    if WRAPPER not in [next(iter(w)) if isinstance(w, dict) else w for w in resolved]:
        raise ValueError(f"--algo genrl needs the env wrapper {WRAPPER} in the settings of {env_id} (env_wrapper)")
    return resolved


def resolved_callback(callback: Any, wrapper: list[Any], env_id: str) -> list[dict[str, Any]]:
    """The entry's ``callback`` with the dataset of a :class:`~sb3_genrl.genrl.demonstrations.DemonstrationCallback`
    that names none filled in: the cached quickstart demonstrations that the wrapper's generator (the cached one) was
    trained on, with their fingerprint; another generator needs the callback's dataset given."""
    from sb3_genrl.genrl.demonstrations import DEMONSTRATION_CALLBACK, callback_entries, with_dataset
    from sb3_genrl.study.state import dataset_fingerprint
    from sb3_genrl.zoo.generators import default_demonstrations, default_generator

    entries = callback_entries(callback, f"{env_id}: callback")
    if not any(path == DEMONSTRATION_CALLBACK and kwargs.get("dataset") is None for path, kwargs in entries):
        return [{path: kwargs} for path, kwargs in entries]
    generator = next(item[WRAPPER]["generator"] for item in wrapper if isinstance(item, dict) and WRAPPER in item)
    if generator != str(default_generator(env_id).resolve()):
        raise ValueError(
            f"{env_id}: the settings learn from demonstrations ({DEMONSTRATION_CALLBACK}) and the "
            f"generator {generator} is not the cached one, whose demonstrations are known: give the "
            f"generator's dataset, -params \"callback:[{{'{DEMONSTRATION_CALLBACK}': {{'dataset': 'DIR'}}}}]\""
        )
    dataset = default_demonstrations(env_id)
    if not (dataset.is_dir() and any(dataset.iterdir())):
        raise FileNotFoundError(
            f"{env_id}: the cached generator's demonstrations {dataset} are missing: remove "
            f"{dataset.parent} to make both again"
        )
    return with_dataset(callback, str(dataset.resolve()), dataset_fingerprint(dataset))
