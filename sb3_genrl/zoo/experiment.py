"""rl-zoo3's ``ExperimentManager`` for GenRL: the generator named in the saved run, and evaluation on tuning goals.

Five things differ from rl-zoo3's own manager, for ``--algo genrl`` only:

- the entry (``-conf``'s file or ``hyperparams/genrl.yml``, with ``-params`` laid over it) is checked before any
  work: every GenRL setting (:func:`sb3_genrl.hyperparams.check_genrl_entry`) and the env wrapper's arguments, so
  that a mistake is reported before a generator is made;
- the env wrapper's generator is resolved before any env is made (the task's quickstart generator is made into the
  cache when missing, :mod:`sb3_genrl.zoo.generators`), and the run's ``config.yml`` records its file and content
  digest, so that ``enjoy`` and ``record_video`` play the policy with the generator it was trained with; a
  :class:`~sb3_genrl.genrl.demonstrations.DemonstrationCallback` without a dataset (the Fetch tasks' entries) gets the
  demonstrations that generator was trained on, recorded in ``config.yml`` with their fingerprint; a model
  continued with ``-i`` must have been trained with that generator;
- every evaluation env (``EvalCallback`` while training, the trials' evaluations with ``-optimize``) draws its goals
  from :data:`~sb3_genrl.hyperparams.TUNING_GOAL_SEED` afresh at each evaluation, the same goals each time and never
  the held-out ones (:data:`~sb3_genrl.hyperparams.EVAL_GOAL_SEED`);
- a study's first trial is the task entry's own settings (when they lie in the sampler's space), so that its best
  trial is never worse on the tuning goals than the settings it would replace;
- a training run on a task with a fast path whose settings name no ``n_envs`` plays an iteration's episodes together
  (``n_envs`` = the entry's ``n_steps``, one step each: the same batch), in one threaded simulation call on all cores
  (:func:`~sb3_genrl.vec_env.latent_vec_env`); its result depends on the seed and the settings, never on the number of
  cores. A study keeps the entry's one env, its trials running side by side (``--n-jobs``).
"""

from __future__ import annotations

import contextlib
import inspect
from collections.abc import Iterator
from typing import Any

import optuna
from rl_zoo3.exp_manager import ExperimentManager
from stable_baselines3.common.save_util import load_from_zip_file
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv, VecEnvWrapper

from sb3_genrl.checks import check_positive_float
from sb3_genrl.data.fingerprints import dataset_fingerprint
from sb3_genrl.genrl.demonstrations import DEMONSTRATION_CALLBACK, callback_entries, with_dataset
from sb3_genrl.genrl.generator_files import check_model_data, generator_digest, generator_file
from sb3_genrl.hyperparams import TUNING_GOAL_SEED, ZOO_KEYS, check_genrl_entry
from sb3_genrl.vec_env import latent_vec_env
from sb3_genrl.wrappers import env_id_has_fast_path
from sb3_genrl.zoo.generators import build_default_generator, default_demonstrations, default_generator
from sb3_genrl.zoo.sampler import entry_params
from sb3_genrl.zoo.wrapper import latent_action, load_generator, resolve_generator

WRAPPER = "sb3_genrl.zoo.latent_action"
# rl-zoo3's keys of an entry that are not GenRL's (check_genrl_entry reads n_timesteps, n_envs, env_wrapper, callback)
RL_ZOO_KEYS = (ZOO_KEYS | {"monitor_kwargs"}) - {"n_timesteps", "n_envs", "env_wrapper", "callback"}


class TuningGoals(VecEnvWrapper):
    """Each ``reset()`` reseeds the envs, env ``i`` with ``seed + i``: every evaluation plays the same goals. With one
    env the goals of an evaluation of ``n`` episodes are those of
    :func:`sb3_genrl.run.train.evaluate_on_goals` with ``goals=n`` and the same seed. With ``seed=None`` (the
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
            env_id = self.env_name.gym_id
            check_entry(
                hyperparams, f"{env_id} (the settings of {self.config}{' with -params' if self.custom_hyperparams else ''})"
            )
            wrapper = resolved_wrapper(hyperparams.get("env_wrapper"), env_id, self.device)
            if self.continue_training:
                check_trained_agent(self.trained_agent, wrapper)
            hyperparams["env_wrapper"] = saved["env_wrapper"] = wrapper
            if hyperparams.get("callback") is not None:
                callback = resolved_callback(hyperparams["callback"], wrapper, self.env_name.gym_id)
                hyperparams["callback"] = saved["callback"] = callback
            if "n_envs" not in hyperparams and not self.optimize_hyperparameters and env_id_has_fast_path(env_id):
                # an iteration's episodes together, in one threaded simulation call (create_envs); the same batch
                hyperparams["n_envs"] = saved["n_envs"] = hyperparams["n_steps"]
                hyperparams["n_steps"] = saved["n_steps"] = 1
        return hyperparams, saved

    def create_envs(self, n_envs: int, eval_env: bool = False, no_log: bool = False) -> VecEnv:
        if self.algo == "genrl" and self.vec_env_class is DummyVecEnv:
            self.vec_env_class = latent_vec_env  # several envs of a task with a fast path: played together
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


def check_entry(hyperparams: dict[str, Any], name: str) -> None:
    """Refuse an rl-zoo3 entry of GenRL settings that GenRL or its env wrapper would refuse, before any work: the
    GenRL settings (:func:`~sb3_genrl.hyperparams.check_genrl_entry`, rl-zoo3's own keys set aside) and the
    arguments of the latent-action wrapper.

    :param hyperparams: the entry as rl-zoo3 read it (``-params`` laid over it)
    :param name: what the entry is, to start the error messages with
    :raises ValueError: naming the setting and what was expected
    """
    entry = {key: value for key, value in hyperparams.items() if key not in RL_ZOO_KEYS}
    if isinstance(entry.get("policy"), str) and "." in entry["policy"]:  # a policy class by its path, for rl-zoo3
        del entry["policy"]
    if isinstance(entry.get("learning_rate"), str):  # rl-zoo3's schedule, "lin_0.001": its value at the start
        entry["learning_rate"] = _schedule_start(entry["learning_rate"], name)
    check_genrl_entry(entry, name)
    check_env_wrapper(hyperparams.get("env_wrapper"), name)


def _schedule_start(schedule: str, name: str) -> float:
    """The start of rl-zoo3's linear schedule ``"lin_0.001"`` (rl-zoo3 reads ``<any name>_<number>``)."""
    try:
        _, value = schedule.split("_")
        return float(value)
    except ValueError:
        raise ValueError(f"{name}: learning_rate must be a number or rl-zoo3's 'lin_<number>', got {schedule!r}") from None


def check_env_wrapper(env_wrapper: Any, name: str) -> None:
    """Refuse an rl-zoo3 ``env_wrapper`` without the latent-action wrapper, or with arguments it would refuse.

    :param env_wrapper: a wrapper's class path, ``{path: {arguments}}``, or a list of them
    :param name: what the settings are, to start the error messages with
    :raises ValueError: naming the entry and what was expected
    """
    ours = []
    for item in env_wrapper if isinstance(env_wrapper, list) else [env_wrapper]:
        if isinstance(item, dict) and len(item) == 1 and isinstance(next(iter(item)), str):
            path, kwargs = next(iter(item.items()))
            if kwargs is not None and not isinstance(kwargs, dict):
                raise ValueError(f"{name}: env_wrapper: the arguments of {path} must be a mapping, got {kwargs!r}")
        elif isinstance(item, str) or item is None:
            path, kwargs = item, None
        else:
            raise ValueError(f"{name}: env_wrapper: expected a wrapper's class path or {{path: {{arguments}}}}, got {item!r}")
        if path == WRAPPER:
            ours.append(kwargs or {})
    if not ours:
        raise ValueError(f"{name}: --algo genrl needs the env wrapper {WRAPPER} (env_wrapper)")
    known = [key for key in inspect.signature(latent_action).parameters if key != "env"]
    for kwargs in ours:
        unknown = sorted(set(kwargs) - set(known))
        if unknown:
            raise ValueError(
                f"{name}: env_wrapper {WRAPPER}: {', '.join(map(repr, unknown))} "
                f"{'is not among its arguments' if len(unknown) == 1 else 'are not among its arguments'} "
                f"({', '.join(known)})"
            )
        for key in ("generator", "generator_sha256"):
            if kwargs.get(key) is not None and not isinstance(kwargs[key], str):
                raise ValueError(f"{name}: env_wrapper {WRAPPER}: {key} must be a file name, got {kwargs[key]!r}")
        if "latent_clip" in kwargs:
            check_positive_float(kwargs["latent_clip"], f"{name}: env_wrapper {WRAPPER}: latent_clip")


def resolved_wrapper(env_wrapper: Any, env_id: str, device: Any = "auto") -> Any:
    """The entry's ``env_wrapper`` with the latent-action wrapper's generator file and digest filled in (the task's
    quickstart generator made into the cache when the entry names none and it is missing). The wrapper's arguments
    are checked (:func:`check_env_wrapper`) before any generator is loaded or made."""
    check_env_wrapper(env_wrapper, f"{env_id}: the settings")
    resolved = []
    for wrapper in env_wrapper if isinstance(env_wrapper, list) else [env_wrapper]:
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
    return resolved


def check_trained_agent(path: str, wrapper: list[Any]) -> None:
    """Refuse to continue training (rl-zoo3's ``-i``) a model zip that was trained with another generator than the
    latent-action wrapper's (the zip records its generator's ``generator_sha256``), or a zip that is not a GenRL model.

    :param path: the model zip
    :param wrapper: the resolved ``env_wrapper`` (:func:`resolved_wrapper`)
    :raises ValueError: naming both generators
    """
    data, _, _ = load_from_zip_file(path, device="cpu", load_data=True)
    check_model_data(path, data)
    recorded = data.get("generator_sha256")
    kwargs = next(item[WRAPPER] for item in wrapper if isinstance(item, dict) and WRAPPER in item)
    given = kwargs["generator_sha256"]
    if recorded is not None and recorded != given:
        trained_with = data.get("generator_path") or generator_file(path)
        raise ValueError(
            f"-i {path} was trained with another generator (SHA-256 {recorded[:12]}..., {trained_with}) than the "
            f"env wrapper's {kwargs['generator']} (SHA-256 {given[:12] + '...' if given else 'unknown'}): continue it with "
            f"the generator it was trained with, -params \"env_wrapper:[{{'{WRAPPER}': {{'generator': "
            f"'{trained_with}'}}}}]\", or train a new model without -i"
        )


def resolved_callback(callback: Any, wrapper: list[Any], env_id: str) -> list[dict[str, Any]]:
    """The entry's ``callback`` with the dataset of a :class:`~sb3_genrl.genrl.demonstrations.DemonstrationCallback`
    that names none filled in: the cached quickstart demonstrations that the wrapper's generator (the cached one) was
    trained on, with their fingerprint; another generator needs the callback's dataset given."""
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
