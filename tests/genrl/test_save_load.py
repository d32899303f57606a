"""GenRL's save and load: round trips, the generator's file, devices, interrupted saves, states switched at load."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
import torch as th
from conftest import (
    FastReachEnv,
    LinearGenerator,
    load_linear_generator,
)
from genrl_test_helpers import GOALS, HindsightReachEnv

from sb3_genrl import GenRL, LatentActionWrapper
from sb3_genrl.genrl import generator_files


def test_save_load_predict_round_trip(tmp_path, monkeypatch):
    generator = LinearGenerator()
    model = GenRL(FastReachEnv(), generator, seed=0).learn(128)
    expected = model.predict(GOALS, deterministic=True)[0]
    model.save(tmp_path / "policy.zip")
    # An in-memory generator is saved beside the model and restored with sb3_genrl.generative.load.
    assert (tmp_path / "policy.generator.pt").exists()
    monkeypatch.setattr(generator_files, "load_generator", load_linear_generator)
    loaded = GenRL.load(tmp_path / "policy.zip")
    np.testing.assert_array_equal(loaded.predict(GOALS, deterministic=True)[0], expected)
    assert loaded.predict_trajectory(GOALS[0]).shape == (5, 2)
    np.testing.assert_allclose(loaded.predict_trajectory(GOALS[0]), generator.decode(expected[0])[0], rtol=1e-6)
    assert loaded.predict_trajectory(GOALS).shape == (4, 5, 2)
    # generator= overrides, a raw env is wrapped, and training goes on.
    override = GenRL.load(tmp_path / "policy.zip", env=FastReachEnv(), generator=generator)
    assert override.generator is generator
    np.testing.assert_array_equal(override.predict(GOALS, deterministic=True)[0], expected)
    override.learn(64, reset_num_timesteps=False)
    assert override.num_timesteps == 192


def test_load_without_generator_still_predicts(tmp_path):
    model = GenRL(FastReachEnv(), _UnsavableGenerator(), seed=0)
    model.save(tmp_path / "policy")
    with pytest.warns(UserWarning, match="no generator found for .*policy"):
        loaded = GenRL.load(tmp_path / "policy")
    assert loaded.predict(GOALS[0], deterministic=True)[0].shape == (2,)
    with pytest.raises(ValueError, match="generator"):
        loaded.predict_trajectory(GOALS[0])


class _UnsavableGenerator(LinearGenerator):
    def save(self, path: str) -> None:
        raise NotImplementedError


def test_generator_path_is_kept(tmp_path, monkeypatch):
    generator_file = tmp_path / "gen.npz"
    LinearGenerator().save(str(generator_file))
    monkeypatch.setattr(generator_files, "load_generator", load_linear_generator)
    model = GenRL(FastReachEnv(), str(generator_file), seed=0)
    assert model.generator_path == str(generator_file)
    model.save(tmp_path / "policy.zip")
    assert not (tmp_path / "policy.generator.pt").exists()
    assert GenRL.load(tmp_path / "policy.zip").generator_path == str(generator_file)


def test_on_paper_task_with_saved_generator(tmp_path):
    """A short run on the hockey task with an untrained beta-VAE saved to a file, then load -> predict_trajectory."""
    from sb3_genrl.generative import make_generator

    generator = make_generator("VAE1", horizon=69, action_dim=7, device="cpu")
    generator.save(str(tmp_path / "vae.pt"))
    model = GenRL("GenRL/Hockey-v0", str(tmp_path / "vae.pt"), n_steps=16, seed=0).learn(32)
    assert model.generator_path == str(tmp_path / "vae.pt") and model.env.get_attr("use_fast_path")[0]
    assert np.isfinite(model.logger.name_to_value["train/mean_reward"])
    model.save(tmp_path / "policy.zip")
    loaded = GenRL.load(tmp_path / "policy.zip", env=gym.make("GenRL/Hockey-v0"))
    goal = np.array([1.0, 0.1], dtype=np.float32)
    np.testing.assert_array_equal(loaded.predict(goal, deterministic=True)[0], model.predict(goal, deterministic=True)[0])
    assert loaded.predict_trajectory(goal).shape == (69, 7)


def test_a_generator_file_is_loaded_onto_the_models_device(tmp_path, monkeypatch):
    """GenRL(..., "vae.pt", device=D), GenRL.load(..., device=D) and load_policy(..., device=D) place the generator
    they load from a file on D."""
    from sb3_genrl.generative import make_generator
    from sb3_genrl.genrl import generator_files
    from sb3_genrl.run.loading import load_policy

    make_generator("VAE1", horizon=69, action_dim=7, device="cpu").save(str(tmp_path / "vae.pt"))
    devices, real_load = [], generator_files.load  # where every path loads a generator file
    monkeypatch.setattr(
        generator_files, "load", lambda path, device="auto": devices.append(str(device)) or real_load(path, device)
    )
    model = GenRL("GenRL/Hockey-v0", str(tmp_path / "vae.pt"), n_steps=8, device="cpu")
    model.save(tmp_path / "policy.zip")
    loaded = GenRL.load(tmp_path / "policy.zip", device="cpu")
    safe = load_policy(tmp_path / "policy.zip", gym.make("GenRL/Hockey-v0"), device="cpu")
    assert devices == ["cpu", "cpu", "cpu"] and safe.generator.device == th.device("cpu")
    assert model.generator.device == model.device and loaded.generator.device == loaded.device == th.device("cpu")


def test_interrupted_save_keeps_the_previous_policy_file(tmp_path, monkeypatch):
    from stable_baselines3.common import base_class

    model = GenRL(FastReachEnv(), LinearGenerator(), seed=0)
    model.save(tmp_path / "policy")  # SB3 adds .zip
    before = (tmp_path / "policy.zip").read_bytes()
    real_save = base_class.save_to_zip_file

    def killed_save(save_path, *args, **kwargs):
        real_save(save_path, *args, **kwargs)
        with open(save_path, "r+b") as file:
            file.truncate(100)  # what a kill during the write leaves behind
        raise KeyboardInterrupt

    monkeypatch.setattr(base_class, "save_to_zip_file", killed_save)
    with pytest.raises(KeyboardInterrupt):
        model.save(tmp_path / "policy.zip")
    assert (tmp_path / "policy.zip").read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["policy.generator.pt", "policy.zip"]


def test_load_switches_the_optional_states_on_and_off(tmp_path):
    """policy_averaging and the hindsight regression changed at load: the saved state of a setting now off is dropped,
    one now on starts afresh from the loaded policy, and the regression's learning rate is the one given."""

    def trained(**kwargs):
        model = GenRL(LatentActionWrapper(HindsightReachEnv(), LinearGenerator()), seed=0, n_steps=16, **kwargs)
        model.learn(32)
        model.save(tmp_path / "model")
        return model

    def load(**kwargs):
        loaded = GenRL.load(tmp_path / "model.zip", env=HindsightReachEnv(), generator=LinearGenerator(), **kwargs)
        loaded.learn(16)  # and it trains on
        return loaded

    contexts = np.array([[0.3, -0.2], [-0.5, 0.4]], dtype=np.float32)
    with_both = trained(policy_averaging=0.9, hindsight_kwargs={"regression_steps": 4})
    plain = GenRL.load(
        tmp_path / "model.zip", env=HindsightReachEnv(), generator=LinearGenerator(), policy_averaging=None
    )  # the policy, not its saved average, acts
    np.testing.assert_allclose(
        plain.predict(contexts, deterministic=True)[0],
        with_both.policy.predict(contexts, deterministic=True)[0],
        rtol=0,
        atol=0,
    )
    switched_off = load(policy_averaging=None, hindsight_kwargs={"regression_steps": 0})
    assert switched_off.policy_average is None and switched_off.hindsight.optimizer is None
    assert "hindsight.optimizer" not in switched_off._get_torch_save_params()[0]
    no_hindsight = load(hindsight_kwargs=None)  # relabelling switched off altogether
    assert no_hindsight.hindsight is None and no_hindsight.policy_average is not None
    faster = load(hindsight_kwargs={"regression_steps": 4, "regression_lr": 1e-2})
    assert faster.hindsight.optimizer.param_groups[0]["lr"] == 1e-2
    assert all(value["step"] == 8 + 4 for value in faster.hindsight.optimizer.state_dict()["state"].values())

    without = trained(hindsight_kwargs={})
    switched_on = GenRL.load(
        tmp_path / "model.zip",
        env=HindsightReachEnv(),
        generator=LinearGenerator(),
        policy_averaging=0.9,
        hindsight_kwargs={"regression_steps": 4},
    )
    # the new average starts as the loaded policy, not as the policy the model was built with
    np.testing.assert_allclose(
        switched_on.predict(contexts, deterministic=True)[0], without.predict(contexts, deterministic=True)[0], rtol=0, atol=0
    )
    assert switched_on.hindsight.optimizer.state_dict()["state"] == {}
    switched_on.learn(16)
    assert all(value["step"] == 4 for value in switched_on.hindsight.optimizer.state_dict()["state"].values())


def _vae(seed: int):
    from sb3_genrl.generative import make_generator

    generator = make_generator("VAE1", horizon=69, action_dim=7, device="cpu")
    generator._reset(seed, "cpu")  # untrained weights drawn from seed
    return generator


def test_a_policy_refuses_a_generator_other_than_the_one_it_was_trained_with(tmp_path, cli):
    from sb3_genrl.run.loading import load_policy

    trained_with, other = _vae(0), _vae(1)
    trained_with.save(str(tmp_path / "vae.pt"))
    GenRL("GenRL/Hockey-v0", str(tmp_path / "vae.pt"), n_steps=8, device="cpu").save(tmp_path / "policy.zip")
    assert GenRL.load(tmp_path / "policy.zip", device="cpu").generator_sha256 == generator_files.generator_digest(trained_with)
    GenRL.load(tmp_path / "policy.zip", device="cpu", generator=trained_with)  # in memory, the same content: accepted
    other.save(str(tmp_path / "vae.pt"))  # a new generator written to the same path
    refused = (
        r"the generator BetaVAE from '.*vae.pt' \(\(latent_dim, T, M\) = \(2, 69, 7\), SHA-256 [0-9a-f]{16}\.\.\.\) "
        r"is not the one .*policy.zip was trained"
    )
    with pytest.raises(ValueError, match=refused):
        GenRL.load(tmp_path / "policy.zip", device="cpu")
    with pytest.raises(ValueError, match=refused):
        load_policy(tmp_path / "policy.zip", gym.make("GenRL/Hockey-v0"))
    with pytest.raises(ValueError, match="is not the one"):
        GenRL.load(tmp_path / "policy.zip", device="cpu", generator=other)  # in memory
    code, _, err = cli("video", "--task", "hockey", "--policy", tmp_path / "policy.zip", "--out", tmp_path / "v.gif")
    assert code == 2 and "is not the one" in err and not (tmp_path / "v.gif").exists()
    # A generator made in memory is saved beside the policy, and that file is checked the same way.
    GenRL("GenRL/Hockey-v0", trained_with, n_steps=8, device="cpu").save(tmp_path / "memory.zip")
    GenRL.load(tmp_path / "memory.zip", device="cpu")
    other.save(str(tmp_path / "memory.generator.pt"))
    with pytest.raises(ValueError, match="memory.generator.pt.* is not the one"):
        GenRL.load(tmp_path / "memory.zip", device="cpu")


def test_a_generator_given_beside_an_env_that_wraps_another_is_refused(tmp_path):
    wrapping, other = _vae(0), _vae(1)
    wrapping.save(str(tmp_path / "vae.pt"))
    env = LatentActionWrapper(gym.make("GenRL/Hockey-v0"), wrapping)
    with pytest.raises(
        ValueError,
        match=r"the generator given, BetaVAE \(\(latent_dim, T, M\) = \(2, 69, 7\), SHA-256 "
        r"[0-9a-f]{16}\.\.\.\), is not the one wrapping the env, BetaVAE ",
    ):
        GenRL(env, other, n_steps=8)
    # The env's own generator, or one of the same content (its file), is accepted.
    assert GenRL(env, wrapping, n_steps=8).generator is wrapping
    assert GenRL(env, str(tmp_path / "vae.pt"), n_steps=8).generator_path == str(tmp_path / "vae.pt")
    unknown = r"LinearGenerator \(\(latent_dim, T, M\) = \(2, 5, 2\), object 0x[0-9a-f]+\), is not "
    with pytest.raises(ValueError, match=unknown):
        GenRL(LatentActionWrapper(FastReachEnv(), LinearGenerator()), LinearGenerator())  # of unknown content


def test_load_accepts_the_constructors_own_policy_kwargs(tmp_path):
    GenRL(FastReachEnv(), LinearGenerator(), n_steps=8, policy_kwargs={"net_arch": [32]}).save(tmp_path / "policy.zip")
    loaded = GenRL.load(
        tmp_path / "policy.zip", env=FastReachEnv(), generator=LinearGenerator(), policy_kwargs={"net_arch": [32]}
    )
    assert loaded.policy_kwargs["net_arch"] == [32]
    with pytest.raises(ValueError, match="policy kwargs do not equal"):  # other ones are still refused, as by SB3
        GenRL.load(tmp_path / "policy.zip", env=FastReachEnv(), generator=LinearGenerator(), policy_kwargs={"net_arch": [64]})


def test_load_refuses_a_generator_file_and_another_algorithms_zip_naming_them(tmp_path):
    from stable_baselines3 import PPO

    _vae(0).save(str(tmp_path / "vae.pt"))
    with pytest.raises(ValueError, match=r"vae.pt is not an SB3 model zip \(a generator file"):
        GenRL.load(tmp_path / "vae.pt")
    PPO("MlpPolicy", "Pendulum-v1", n_steps=8, batch_size=8).save(tmp_path / "ppo.zip")
    with pytest.raises(ValueError, match="ppo.zip is not a GenRL model: it holds a ActorCriticPolicy policy"):
        GenRL.load(tmp_path / "ppo.zip")


def test_set_env_with_an_env_wrapped_with_another_generator_is_refused(tmp_path):
    """set_env with a LatentActionWrapper of another generator: the model would train on it while it keeps, saves and
    evaluates with its own; refused. The same content, or a raw env (wrapped with the model's), is accepted."""
    own, other = _vae(0), _vae(1)
    model = GenRL("GenRL/Hockey-v0", own, n_steps=8, device="cpu")
    with pytest.raises(
        ValueError,
        match=r"the env is wrapped with the generator BetaVAE \(\(latent_dim, T, M\) = \(2, 69, 7\), SHA-256 [0-9a-f]{16}"
        r"\.\.\.\), not with this model's own, BetaVAE .*: the policy would train on the env's",
    ):
        model.set_env(LatentActionWrapper(gym.make("GenRL/Hockey-v0"), other))
    own.save(str(tmp_path / "own.pt"))
    from sb3_genrl.generative import load

    model.set_env(LatentActionWrapper(gym.make("GenRL/Hockey-v0"), load(str(tmp_path / "own.pt"), device="cpu")))
    model.set_env(gym.make("GenRL/Hockey-v0"))
    assert model.generator is own and model.env.get_attr("generator")[0] is own


def test_load_with_an_env_wrapped_with_another_generator_is_refused(tmp_path):
    """GenRL.load(path, env=wrapped with B) of a model trained with A: refused (it used to train on B and save A); a
    model loaded without its generator takes the env's only when it is the one the model recorded."""
    own, other = _vae(0), _vae(1)
    GenRL("GenRL/Hockey-v0", own, n_steps=8, device="cpu").save(tmp_path / "model.zip")
    with pytest.raises(ValueError, match=r"the env is wrapped with the generator BetaVAE .*, not with .*model.zip's own"):
        GenRL.load(tmp_path / "model.zip", env=LatentActionWrapper(gym.make("GenRL/Hockey-v0"), other), device="cpu")
    loaded = GenRL.load(tmp_path / "model.zip", env=LatentActionWrapper(gym.make("GenRL/Hockey-v0"), own), device="cpu")
    assert generator_files.generator_digest(loaded.generator) == generator_files.generator_digest(own)
    (tmp_path / "model.generator.pt").unlink()  # no generator of its own: the env's is checked against the record
    with pytest.raises(ValueError, match=r"the generator BetaVAE .* is not the one .*model.zip was trained with"):
        GenRL.load(tmp_path / "model.zip", env=LatentActionWrapper(gym.make("GenRL/Hockey-v0"), other), device="cpu")
    adopted = GenRL.load(tmp_path / "model.zip", env=LatentActionWrapper(gym.make("GenRL/Hockey-v0"), own), device="cpu")
    assert adopted.generator is own


def test_a_model_loaded_by_a_relative_path_keeps_its_generator_when_saved_elsewhere(tmp_path, monkeypatch):
    """Loaded as d1/model.zip from its parent folder and saved to d2/: the new zip finds its generator from any
    folder (it used to record the relative path d1/model.generator.pt and load elsewhere with none, silently)."""
    generator = _vae(0)
    (tmp_path / "work").mkdir()
    monkeypatch.chdir(tmp_path / "work")
    GenRL("GenRL/Hockey-v0", generator, n_steps=8, device="cpu").save("d1/model.zip")
    GenRL.load("d1/model.zip", device="cpu").save("d2/model.zip")
    GenRL("GenRL/Hockey-v0", "d1/model.generator.pt", n_steps=8, device="cpu").save("d3/model.zip")  # a file, relative
    GenRL.load("d3/model.zip", device="cpu").save("d4/model.zip")
    monkeypatch.chdir(tmp_path)
    for name in ("d2", "d4"):
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # no warning: the generator is found
            loaded = GenRL.load(tmp_path / "work" / name / "model.zip", device="cpu")
        assert generator_files.generator_digest(loaded.generator) == generator_files.generator_digest(generator)
    assert (tmp_path / "work" / "d2" / "model.generator.pt").is_file()  # an in-memory generator travels beside its zip


def test_a_model_whose_generator_file_is_gone_saves_it_beside_and_one_without_any_warns(tmp_path):
    generator = _vae(0)
    generator.save(str(tmp_path / "vae.pt"))
    model = GenRL("GenRL/Hockey-v0", str(tmp_path / "vae.pt"), n_steps=8, device="cpu")
    model.save(tmp_path / "kept.zip")
    (tmp_path / "vae.pt").unlink()
    model.save(tmp_path / "moved.zip")  # the file it was built from is gone: saved beside
    assert not (tmp_path / "kept.generator.pt").exists() and (tmp_path / "moved.generator.pt").is_file()
    assert GenRL.load(tmp_path / "moved.zip", device="cpu").generator is not None
    with pytest.warns(UserWarning, match=r"no generator found for .*kept.zip \(none of '.*vae.pt', '.*kept.generator.pt'"):
        loaded = GenRL.load(tmp_path / "kept.zip", device="cpu")
    assert loaded.generator is None


def test_a_model_zip_without_a_generator_hash_is_flagged(tmp_path):
    """A zip of an older version (no generator_sha256): its generator cannot be checked, and a warning says so."""
    import json
    import zipfile

    GenRL("GenRL/Hockey-v0", _vae(0), n_steps=8, device="cpu").save(tmp_path / "model.zip")
    with zipfile.ZipFile(tmp_path / "model.zip") as archive:
        entries = {name: archive.read(name) for name in archive.namelist()}
    data = json.loads(entries["data"])
    del data["generator_sha256"]
    entries["data"] = json.dumps(data).encode()
    with zipfile.ZipFile(tmp_path / "older.zip", "w") as archive:
        for name, content in entries.items():
            archive.writestr(name, content)
    (tmp_path / "model.generator.pt").rename(tmp_path / "older.generator.pt")
    with pytest.warns(UserWarning, match=r"older.zip was saved without its generator's SHA-256 \(by an older sb3-genrl\)"):
        assert GenRL.load(tmp_path / "older.zip", device="cpu").generator is not None


def test_load_policy_names_another_algorithms_zip_first_and_where_a_moved_generator_goes(tmp_path):
    from stable_baselines3 import SAC

    from sb3_genrl.run.loading import load_policy
    from sb3_genrl.video import record_video

    SAC("MlpPolicy", "Pendulum-v1", learning_starts=0).save(tmp_path / "sac.zip")  # no generator anywhere near it
    with pytest.raises(ValueError, match="sac.zip is not a GenRL model"):
        load_policy(tmp_path / "sac.zip", gym.make("GenRL/Hockey-v0"))
    _vae(0).save(str(tmp_path / "vae.pt"))
    GenRL("GenRL/Hockey-v0", str(tmp_path / "vae.pt"), n_steps=8, device="cpu").save(tmp_path / "policy.zip")
    (tmp_path / "vae.pt").rename(tmp_path / "moved.pt")
    with pytest.raises(ValueError, match=r"pass the generator file \(generator=...\), or copy it beside the zip as .*policy"):
        load_policy(tmp_path / "policy.zip", gym.make("GenRL/Hockey-v0"))
    run = tmp_path / "run"  # a finished run of another algorithm: named as such by genrl video
    run.mkdir()
    (run / "run_record.json").write_text('{"algorithm": "latent-sac"}')
    with pytest.raises(ValueError, match="holds no genrl_policy.zip; it is a latent-sac run, not a GenRL one"):
        record_video("hockey", tmp_path / "v.gif", policy=run)
