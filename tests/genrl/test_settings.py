"""The check of GenRL's settings (sb3_genrl/genrl/settings.py) and the command line's --genrl-kwargs."""

from __future__ import annotations

import argparse
import re

import gymnasium as gym
import pytest
from conftest import FastReachEnv, LinearGenerator, ReachEnv

from sb3_genrl import GenRL, LatentActionWrapper
from sb3_genrl.genrl import check_genrl_settings


def test_check_genrl_settings_refuses_unknown_names_and_policies():
    settings = {
        "policy": "ContextStdPolicy",
        "target_kl": 0.03,
        "policy_kwargs": {"net_arch": [8]},
        "hindsight_kwargs": {"history": 2},
    }
    checked = check_genrl_settings(settings)
    assert checked == settings and checked is not settings and type(checked) is dict  # a plain copy
    assert checked["hindsight_kwargs"] is not settings["hindsight_kwargs"]
    with pytest.raises(ValueError, match=r"--genrl-kwargs: 'target_kll' is not a GenRL setting"):
        check_genrl_settings({"target_kll": 0.03}, "--genrl-kwargs")
    with pytest.raises(ValueError, match=r"'a', 'seed' are not GenRL settings"):  # where it runs is not a setting
        check_genrl_settings({"seed": 1, "a": 2})
    with pytest.raises(ValueError, match="unknown policy 'CnnPolicy'"):
        check_genrl_settings({"policy": "CnnPolicy"})
    with pytest.raises(TypeError, match="expected a dict"):
        check_genrl_settings([("target_kl", 0.03)])
    # the values GenRL would refuse, before any work: alone, and against the others' defaults (e_step="trpo")
    with pytest.raises(ValueError, match="--genrl-kwargs: value_history must be a positive integer, got 0"):
        check_genrl_settings({"value_history": 0}, "--genrl-kwargs")
    with pytest.raises(ValueError, match="hindsight_kwargs needs e_step='trpo'"):
        check_genrl_settings({"hindsight_kwargs": {}, "e_step": "kl_penalty"})
    assert check_genrl_settings({"hindsight_kwargs": {"history": 2}}) == {"hindsight_kwargs": {"history": 2}}
    assert check_genrl_settings({"hindsight_kwargs": None, "e_step": "kl_penalty"}) == {
        "hindsight_kwargs": None,
        "e_step": "kl_penalty",
    }


def test_genrl_kwargs_argument_parses_and_checks_json():
    from sb3_genrl.run.train import genrl_kwargs_argument, genrl_kwargs_override_argument

    # settings laid over a task's are checked as any others: one hindsight_kwargs dict holds the settings that
    # depend on each other
    text = '{"hindsight_kwargs": {"regression_steps": 8}}'
    assert genrl_kwargs_override_argument(text) == genrl_kwargs_argument(text) == {"hindsight_kwargs": {"regression_steps": 8}}
    for parse in (genrl_kwargs_argument, genrl_kwargs_override_argument):
        with pytest.raises(argparse.ArgumentTypeError, match="needs regression_steps > 0"):
            parse('{"hindsight_kwargs": {"regression_weighted": true}}')
        with pytest.raises(argparse.ArgumentTypeError, match="'x' is not a GenRL setting"):
            parse('{"x": 1}')

    assert genrl_kwargs_argument('{"target_kl": 0.03}') == {"target_kl": 0.03}
    for text, message in (("{", "not JSON"), ("[1]", "expected a dict"), ('{"x": 1}', "'x' is not a GenRL setting")):
        with pytest.raises(argparse.ArgumentTypeError, match=message):
            genrl_kwargs_argument(text)


@pytest.mark.parametrize(
    ("hindsight_kwargs", "message"),
    [
        ({"regression_steps": -1}, r"hindsight_kwargs\['regression_steps'\] must be an integer >= 0, got -1"),
        ({"regression_steps": 1.5}, r"hindsight_kwargs\['regression_steps'\] must be an integer >= 0"),
        ({"regression_steps": True}, r"hindsight_kwargs\['regression_steps'\] must be an integer >= 0"),
        ({"regression_lr": 0.0}, r"hindsight_kwargs\['regression_lr'\] must be a finite positive number"),
        ({"regression_batch_size": 0}, r"hindsight_kwargs\['regression_batch_size'\] must be an integer >= 1"),
        ({"regression_batch_size": True}, r"hindsight_kwargs\['regression_batch_size'\] must be an integer >= 1"),
        (
            {"regression_steps": 4, "regression_weighted": 1},
            r"hindsight_kwargs\['regression_weighted'\] must be True or False",
        ),
        (
            {"regression_weighted": True},
            r"hindsight_kwargs\['regression_weighted'\] weights the regression's pulls, which "
            "needs regression_steps > 0",
        ),
        ({"refit_every": -64}, r"hindsight_kwargs\['refit_every'\] must be an integer >= 0, got -64"),
        ({"refit_every": 64, "refit_steps": 0}, r"hindsight_kwargs\['refit_steps'\] must be an integer >= 1, got 0"),
        ({"refit_every": 64, "refit_start": 0}, r"hindsight_kwargs\['refit_start'\] must be an integer >= 1 or None"),
        (
            {"refit_start": 512},
            r"hindsight_kwargs\['refit_start'\] is the episode of the first refit, which needs "
            "refit_every > 0",
        ),
        ({"history": -1}, r"hindsight_kwargs\['history'\] must be an integer >= 0, got -1"),
        ({"history": 1.5}, r"hindsight_kwargs\['history'\] must be an integer >= 0"),
        ({"histroy": 2}, r"hindsight_kwargs: 'histroy' not among its settings \(history, regression_steps"),
        ("yes", "hindsight_kwargs must be a dict or None, got 'yes'"),
        (True, "hindsight_kwargs must be a dict or None, got True"),
    ],
    ids=[
        "steps-negative",
        "steps-fraction",
        "steps-bool",
        "lr-zero",
        "batch-zero",
        "batch-bool",
        "weighted-int",
        "weighted-without-steps",
        "refit-negative",
        "refit-steps-zero",
        "refit-start-zero",
        "refit-start-without-every",
        "history-negative",
        "history-fraction",
        "unknown-key",
        "string",
        "bool",
    ],
)
def test_hindsight_kwargs_are_checked(hindsight_kwargs, message):
    with pytest.raises(ValueError, match=message):
        GenRL(FastReachEnv(), LinearGenerator(), hindsight_kwargs=hindsight_kwargs)
    with pytest.raises(ValueError, match=f"--genrl-kwargs: {message}"):
        check_genrl_settings({"hindsight_kwargs": hindsight_kwargs}, "--genrl-kwargs")


def test_hindsight_is_checked():
    with pytest.raises(ValueError, match="hindsight_kwargs needs e_step='trpo'"):
        GenRL(FastReachEnv(), LinearGenerator(), hindsight_kwargs={}, e_step="kl_penalty")
    model = GenRL(FastReachEnv(), LinearGenerator(), seed=0, hindsight_kwargs={})  # its task has no hindsight(info)
    with pytest.raises(ValueError, match=r"info\['hindsight'\]"):
        model.learn(64)
    assert model.num_timesteps == 1  # refused at the first pull, not after the rollout
    dict_env = LatentActionWrapper(
        ReachEnv(),
        LinearGenerator(),
        context=lambda obs: {"goal": obs[:2]},
        context_space=gym.spaces.Dict({"goal": gym.spaces.Box(-1, 1, (2,))}),
    )
    with pytest.raises(ValueError, match="hindsight_kwargs relabels Box contexts"):
        GenRL("MultiInputPolicy", dict_env, hindsight_kwargs={})


def test_one_episode_per_batch_is_refused_as_sb3_and_sb3_contrib_refuse_it():
    from conftest import FastReachEnv, LinearGenerator

    for expected in (ValueError, AssertionError):  # sb3-genrl's convention and SB3's (PPO, TRPO: AssertionError)
        with pytest.raises(expected, match="n_steps \\* n_envs >= 2"):
            GenRL(FastReachEnv(), LinearGenerator(), n_steps=1)


def test_a_batch_size_of_zero_is_refused_naming_it():
    with pytest.raises(ValueError, match="batch_size must be a positive integer, got 0"):
        GenRL(FastReachEnv(), LinearGenerator(), batch_size=0)
    with pytest.raises(ValueError, match="batch_size must be a positive integer, got 0"):
        check_genrl_settings({"batch_size": 0})


def test_the_settings_table_agrees_with_genrl_s_signature():
    """settings.py holds its own table of the settings (no import of GenRL); GenRL's signature has the same names and
    defaults, and its policy aliases are the table's."""
    import inspect

    from sb3_genrl.genrl.settings import NOT_SETTINGS, POLICY_ALIASES, SETTINGS

    parameters = inspect.signature(GenRL.__init__).parameters
    assert list(SETTINGS) == [name for name in parameters if name not in NOT_SETTINGS]
    assert {name: setting.default for name, setting in SETTINGS.items()} == {
        name: parameters[name].default for name in SETTINGS
    }
    assert GenRL.policy_aliases == POLICY_ALIASES
    assert all(setting.accepts(setting.default) for setting in SETTINGS.values())  # every default passes its own check


def _setting_id(item):
    return "-".join(f"{key}={value}" for key, value in item.items()) if isinstance(item, dict) else None


STOPS_LEARNING = [
    ({"target_kl": -0.01}, "target_kl must be a finite number > 0 (the E-step's KL bound), got -0.01"),
    ({"target_kl": 0}, "target_kl must be a finite number > 0 (the E-step's KL bound), got 0"),
    ({"target_kl": float("nan")}, "target_kl must be a finite number > 0 (the E-step's KL bound), got nan"),
    ({"target_kl": float("inf")}, "target_kl must be a finite number > 0 (the E-step's KL bound), got inf"),
    ({"line_search_max_iter": 0}, "line_search_max_iter must be a positive integer, got 0"),
    ({"cg_max_steps": 0}, "cg_max_steps must be a positive integer, got 0"),
    ({"cg_damping": -0.1}, "cg_damping must be a finite number >= 0, got -0.1"),
    ({"line_search_shrinking_factor": 1.0}, "line_search_shrinking_factor must be a number between 0 and 1 (exclusive)"),
    ({"line_search_shrinking_factor": 0}, "line_search_shrinking_factor must be a number between 0 and 1 (exclusive)"),
    ({"kl_coef": 0.0, "e_step": "kl_penalty"}, "kl_coef must be a finite number > 0, got 0.0"),
    (
        {"learning_rate": 0.0},
        "learning_rate must be a finite number > 0 or a schedule (a callable of the remaining progress), got 0.0",
    ),
    ({"e_step_learning_rate": -1e-3}, "e_step_learning_rate must be a finite number > 0, got -0.001"),
    ({"n_critic_updates": 0}, "n_critic_updates must be a positive integer, got 0"),
    ({"n_e_step_epochs": 0}, "n_e_step_epochs must be a positive integer, got 0"),
    ({"n_steps": 0}, "n_steps must be a positive integer, got 0"),
    ({"latent_clip": -1.0}, "latent_clip must be a finite number > 0, got -1.0"),
    ({"latent_clip": 0}, "latent_clip must be a finite number > 0, got 0"),
    ({"latent_clip": float("inf")}, "latent_clip must be a finite number > 0, got inf"),
]


@pytest.mark.parametrize(("settings", "message"), STOPS_LEARNING, ids=_setting_id)
def test_settings_that_stop_learning_are_refused_wherever_settings_are_taken(settings, message, tmp_path):
    """The constructor, the check of --genrl-kwargs and the settings files, and GenRL.load with settings: each refuses
    the value before any work (they used to run to the end with train/kl at 0 and a flat curve)."""
    message = re.escape(message)
    with pytest.raises(ValueError, match=message):
        GenRL(FastReachEnv(), LinearGenerator(), **settings)
    with pytest.raises(ValueError, match=f"--genrl-kwargs: {message}"):
        check_genrl_settings(settings, "--genrl-kwargs")
    GenRL(FastReachEnv(), LinearGenerator(), n_steps=8, e_step=settings.get("e_step", "trpo")).save(tmp_path / "model.zip")
    with pytest.raises(ValueError, match=rf"GenRL\.load\(.*model\.zip\): {message}"):
        GenRL.load(tmp_path / "model.zip", env=FastReachEnv(), generator=LinearGenerator(), **settings)


@pytest.mark.parametrize(
    ("settings", "message"),
    [
        ({"target_kl": "0.01"}, r"target_kl must be a finite number > 0 \(the E-step's KL bound\), got '0.01' \(str\)"),
        ({"n_critic_updates": 2.5}, "n_critic_updates must be a positive integer, got 2.5"),
        ({"n_em_iterations": True}, "n_em_iterations must be a positive integer, got True"),
        ({"normalize_advantage": "yes"}, r"normalize_advantage must be True or False, got 'yes' \(str\)"),
        ({"e_step": 1}, "e_step must be 'trpo' or 'kl_penalty', got 1"),
        ({"policy_kwargs": "big"}, r"policy_kwargs must be a dict or None, got 'big' \(str\)"),
        (
            {"policy_kwargs": {"net_arch": "big"}},
            r"policy_kwargs\['net_arch'\] must be a list of positive layer sizes or a dict of them for 'pi' and 'vf', "
            r"got 'big' \(str\)",
        ),
        ({"policy_kwargs": {"net_arch": {"pi": [64, -1]}}}, r"policy_kwargs\['net_arch'\] must be a list of positive"),
        ({"policy_kwargs": {"net_arch": {"actor": [64]}}}, r"policy_kwargs\['net_arch'\] must be a list of positive"),
        ({"policy_kwargs": {"activation_fn": "relu"}}, r"policy_kwargs\['activation_fn'\] must be a torch.nn.Module class"),
        ({"policy_kwargs": {"log_std_init": "0"}}, r"policy_kwargs\['log_std_init'\] must be a finite number, got '0'"),
        ({"policy_kwargs": {"net_arhc": [8]}}, r"policy_kwargs: 'net_arhc' is not an argument of ActorCriticPolicy"),
        ({"policy_kwargs": {"use_sde": True}}, r"policy_kwargs: 'use_sde' is not an argument of ActorCriticPolicy"),
        (
            {"policy_kwargs": {"optimizer_kwargs": {"lr": 0.1}}},
            r"policy_kwargs\['optimizer_kwargs'\]: 'lr' is set by SB3",
        ),
        ({"policy_kwargs": {"optimizer_kwargs": {"eps": "x"}}}, r"policy_kwargs\['optimizer_kwargs'\] .* Adam refuses them"),
        (
            {"policy_kwargs": {"optimizer_kwargs": {"betas": (1.5, 0.9)}}},
            r"policy_kwargs\['optimizer_kwargs'\] .* Adam refuses them \(Invalid beta",
        ),
        (
            {"policy_kwargs": {"optimizer_kwargs": {"foo": 1}}},
            r"policy_kwargs\['optimizer_kwargs'\] .*unexpected keyword argument 'foo'",
        ),
        (
            {"policy_kwargs": {"features_extractor_kwargs": {"x": 1}}},
            r"policy_kwargs\['features_extractor_kwargs'\]: 'x' not an argument of BoxScaler",
        ),
        ({"hindsight_kwargs": {"history": "a"}}, r"hindsight_kwargs\['history'\] must be an integer >= 0, got 'a'"),
        (
            {"hindsight_kwargs": {"regression_lr": "abc"}},
            r"hindsight_kwargs\['regression_lr'\] must be a finite positive number, got 'abc'",
        ),
        (
            {"hindsight_kwargs": {"refit_steps": float("inf")}},
            r"hindsight_kwargs\['refit_steps'\] must be an integer >= 1, got inf",
        ),
    ],
    ids=_setting_id,
)
def test_a_value_of_the_wrong_type_is_refused_in_one_line_before_any_work(settings, message):
    """A string for a number, a float for an integer, ``net_arch: "big"``: refused by the check every path takes, not
    a TypeError or an AssertionError from SB3 partway through."""
    with pytest.raises(ValueError, match=f"--genrl-kwargs: {message}"):
        check_genrl_settings(settings, "--genrl-kwargs")
    with pytest.raises(ValueError, match=message):
        GenRL(FastReachEnv(), LinearGenerator(), **settings)


@pytest.mark.parametrize(
    ("settings", "message"),
    [
        ({"success_kl_floor": 0.0}, r"success_kl_floor must be between 0 \(exclusive\) and 1, or None, got 0.0"),
        ({"success_kl_floor": 1.5}, r"success_kl_floor must be between 0 \(exclusive\) and 1, or None, got 1.5"),
        ({"success_kl_floor": 0.1}, r"success_kl_floor .* needs hindsight_kwargs with refit_every > 0"),
        (
            {"success_kl_floor": 0.1, "hindsight_kwargs": {"history": 0}},
            r"success_kl_floor .* needs hindsight_kwargs with refit_every > 0",
        ),
    ],
    ids=_setting_id,
)
def test_the_kl_bound_by_success_is_checked(settings, message):
    """A floor outside (0, 1], or one without the refits' buffer (which stores each pull's success), is refused before
    any work."""
    with pytest.raises(ValueError, match=message):
        GenRL(FastReachEnv(), LinearGenerator(), **settings)
    with pytest.raises(ValueError, match=f"--genrl-kwargs: {message}"):
        check_genrl_settings(settings, "--genrl-kwargs")


def test_settings_given_to_load_are_checked_with_the_saved_ones(tmp_path):
    GenRL(FastReachEnv(), LinearGenerator(), n_steps=8, e_step="kl_penalty").save(tmp_path / "model.zip")
    with pytest.raises(ValueError, match=r"GenRL.load\(.*model.zip\): hindsight_kwargs needs e_step='trpo'"):
        GenRL.load(tmp_path / "model.zip", env=FastReachEnv(), generator=LinearGenerator(), hindsight_kwargs={})
    loaded = GenRL.load(tmp_path / "model.zip", env=FastReachEnv(), generator=LinearGenerator(), kl_coef=0.5)
    assert loaded.kl_coef == 0.5 and loaded.e_step == "kl_penalty"


def test_latent_clip_of_an_env_already_wrapped_must_be_the_wrappers(tmp_path):
    """GenRL's latent_clip is the half-width of the wrapped env's action box, not only a record: an env wrapped with
    another is refused (it used to be recorded in the model while the box stayed as wrapped)."""
    generator = LinearGenerator()
    wrapped = LatentActionWrapper(FastReachEnv(), generator, latent_clip=2.0)
    with pytest.raises(ValueError, match=r"the env is wrapped with latent_clip=2.0, not 1.0: .* give both the same"):
        GenRL(wrapped, latent_clip=1.0)
    with pytest.raises(ValueError, match="the env is wrapped with latent_clip=2.0, not 3.0"):
        GenRL(wrapped)  # GenRL's default
    model = GenRL(wrapped, latent_clip=2.0, n_steps=8)
    assert model.latent_clip == 2.0 and model.action_space.high.tolist() == [2.0, 2.0]
    model.save(tmp_path / "model.zip")  # loaded onto an env: the raw one wrapped with the saved latent_clip
    for env in (FastReachEnv(), LatentActionWrapper(FastReachEnv(), generator, latent_clip=2.0)):
        loaded = GenRL.load(tmp_path / "model.zip", env=env, generator=generator)
        assert loaded.latent_clip == 2.0 and loaded.env.get_attr("latent_clip") == [2.0]
    with pytest.raises(ValueError, match="the env is wrapped with latent_clip=3.0, not 2.0"):
        GenRL.load(tmp_path / "model.zip", env=LatentActionWrapper(FastReachEnv(), generator), generator=generator)
    raw = GenRL(FastReachEnv(), generator, latent_clip=1.5, n_steps=8)  # a raw env is wrapped with it
    assert raw.action_space.high.tolist() == [1.5, 1.5]
    with pytest.raises(ValueError, match="the env is wrapped with latent_clip=2.0, not 1.5"):
        raw.set_env(wrapped)
    # a uniform prior's box is its support, [-1, 1], whatever latent_clip is
    uniform = LatentActionWrapper(FastReachEnv(), LinearGenerator(prior="uniform"), latent_clip=2.0)
    assert GenRL(uniform, n_steps=8).action_space.high.tolist() == [1.0, 1.0]
