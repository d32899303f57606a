"""Tests of sb3_genrl.generative: training on a synthetic two-factor family, save/load, validation, presets, CLI."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

import sb3_genrl
from sb3_genrl.cli import main as cli_main
from sb3_genrl.generative import (
    PRESETS,
    BetaVAE,
    InfoGAN,
    TrajectoryGenerator,
    load,
    make_generator,
    train_generator,
)
from sb3_genrl.generative.common import (
    MIN_STD,
    minibatch_indices,
    normalisation_statistics,
    selection_mse,
    split_train_validation,
)
from sb3_genrl.generative.synthetic import sine_ramp_basis, sine_ramp_trajectories

HORIZON, ACTION_DIM = 20, 3
EPOCHS = 30


@pytest.fixture(scope="module")
def family() -> tuple[np.ndarray, np.ndarray]:
    train, _ = sine_ramp_trajectories(2000, HORIZON, ACTION_DIM, rng=0)
    test, _ = sine_ramp_trajectories(200, HORIZON, ACTION_DIM, rng=1)
    return train, test


@pytest.fixture(scope="module")
def vae(family) -> BetaVAE:
    return BetaVAE(HORIZON, ACTION_DIM, 2, beta=0.01, device="cpu").fit(
        family[0], epochs=EPOCHS, seed=0, progress_bar=False, eval_every=5
    )


@pytest.fixture(scope="module")
def gan(family) -> InfoGAN:
    return InfoGAN(HORIZON, ACTION_DIM, 2, info_weight=1.5, device="cpu").fit(
        family[0], epochs=EPOCHS, seed=0, progress_bar=False, eval_every=5
    )


def family_residual(trajectories: np.ndarray) -> np.ndarray:
    """Mean squared residual of each trajectory after a least-squares fit of the family's two factors (a, b)."""
    sine, ramp = sine_ramp_basis(HORIZON, ACTION_DIM)
    basis = np.stack([sine.ravel(), ramp.ravel()], axis=1)
    flat = trajectories.reshape(len(trajectories), -1).T.astype(np.float64)
    coefficients, *_ = np.linalg.lstsq(basis, flat, rcond=None)
    return ((flat - basis @ coefficients) ** 2).mean(axis=0)


def test_synthetic_family_has_two_factors():
    trajectories, factors = sine_ramp_trajectories(5, HORIZON, ACTION_DIM, rng=3)
    assert family_residual(trajectories).max() < 1e-10
    t, j = 7, 2
    expected = factors[:, 0] * np.sin(2 * np.pi * t / HORIZON + 2 * np.pi * j / ACTION_DIM) + factors[:, 1] * t / HORIZON
    np.testing.assert_allclose(trajectories[:, t, j], expected, rtol=1e-5)


def test_vae_reconstructs_held_out_and_samples_stay_in_family(vae, family):
    _, test = family
    variance = test.var()
    mean, log_std = vae.encode(test)
    assert mean.shape == log_std.shape == (len(test), 2)
    reconstruction = vae.decode(mean)
    assert reconstruction.dtype == np.float32 and reconstruction.shape == test.shape
    assert np.mean((reconstruction - test) ** 2) / variance < 0.1
    samples = vae.decode(vae.sample_prior(300, rng=0))
    assert family_residual(samples).mean() / variance < 0.05
    # samples are spread over the family, not one trajectory
    assert samples.reshape(300, -1).std(axis=0).mean() > 0.3 * test.reshape(len(test), -1).std(axis=0).mean()


def test_vae_history_and_model_selection(vae, family):
    assert [entry["epoch"] for entry in vae.history] == list(range(5, EPOCHS + 1, 5))
    assert {"loss", "reconstruction", "kl", "selection_mse"} <= set(vae.history[0])
    best = min(vae.history, key=lambda entry: entry["selection_mse"])
    assert vae.best_epoch == best["epoch"]
    # loss = reconstruction + beta * KL (eq. 9), per epoch average
    entry = vae.history[-1]
    assert entry["loss"] == pytest.approx(entry["reconstruction"] + 0.01 * entry["kl"], rel=1e-4)
    assert vae.history[-1]["reconstruction"] < vae.history[0]["reconstruction"]


def test_infogan_trains_without_collapse(gan, family):
    train, _ = family
    samples = gan.decode(gan.sample_prior(500, rng=0))
    assert np.all(np.isfinite(samples))
    data_std = train.reshape(len(train), -1).std(axis=0)
    moving = data_std > 1e-3  # e.g. joint 0 at t = 0 is 0 in every trajectory
    ratio = samples.reshape(500, -1).std(axis=0)[moving] / data_std[moving]
    assert np.median(ratio) > 0.3
    assert {"discriminator", "generator", "info", "selection_mse"} <= set(gan.history[-1])


def test_decode_is_deterministic_and_matches_decode_torch(vae, gan):
    for model in (vae, gan):
        alpha = model.sample_prior(16, rng=5)
        first, second = model.decode(alpha), model.decode(alpha)
        np.testing.assert_array_equal(first, second)
        # eval-mode batch norm: a trajectory does not depend on the rest of the batch (up to float32 kernel rounding)
        np.testing.assert_allclose(model.decode(alpha[:1]), first[:1], atol=1e-5)
        with torch.no_grad():
            np.testing.assert_allclose(model.decode_torch(torch.as_tensor(alpha)).numpy(), first, rtol=1e-6)
        assert model.decode(alpha[0]).shape == (1, HORIZON, ACTION_DIM)


@pytest.mark.parametrize("name", ["vae", "gan"])
def test_save_load_round_trip(name, vae, gan, tmp_path):
    model = vae if name == "vae" else gan
    path = tmp_path / "model.pt"
    model.save(str(path))
    restored = load(path, device="cpu")
    assert type(restored) is type(model) and isinstance(restored, TrajectoryGenerator)
    assert restored.config() == model.config() and restored.prior == model.prior
    assert restored.saved_version == sb3_genrl.__version__
    assert restored.best_epoch == model.best_epoch and restored.history == model.history
    alpha = model.sample_prior(10, rng=1)
    np.testing.assert_array_equal(restored.decode(alpha), model.decode(alpha))
    payload = torch.load(path, weights_only=True)
    assert payload["format"] == "sb3_genrl.generative.TrajectoryGenerator"
    assert json.loads(payload["config"])["latent_dim"] == 2


def test_load_rejects_foreign_files(tmp_path):
    random_bytes = tmp_path / "random.pt"
    random_bytes.write_bytes(np.random.default_rng(0).bytes(4096))
    text = tmp_path / "notes.txt"
    text.write_text("not a model\n")
    unmarked = tmp_path / "unmarked.pt"
    torch.save({"weights": torch.zeros(3)}, unmarked)
    for path in (random_bytes, text):
        with pytest.raises(ValueError, match="torch.load could not read it") as error:
            load(path)
        assert str(path) in str(error.value)
    with pytest.raises(ValueError, match="lacks the format marker") as error:
        load(unmarked)
    assert str(unmarked) in str(error.value)
    with pytest.raises(FileNotFoundError):
        load(tmp_path / "missing.pt")


def test_latent_validation(vae):
    with pytest.raises(ValueError, match="shape"):
        vae.decode(np.zeros((4, 3), dtype=np.float32))
    with pytest.raises(ValueError, match="shape"):
        vae.decode(np.zeros((2, 2, 2), dtype=np.float32))
    for bad in (np.nan, np.inf):
        alpha = np.zeros((4, 2), dtype=np.float32)
        alpha[1, 0] = bad
        with pytest.raises(ValueError, match="non-finite"):
            vae.decode(alpha)
    with pytest.raises(ValueError, match="shape"):
        vae.decode_torch(torch.zeros(3))


def test_training_data_validation():
    model = BetaVAE(HORIZON, ACTION_DIM, 2, beta=0.01, device="cpu")
    with pytest.raises(ValueError, match=r"\(N, 20, 3\)"):
        model.fit(np.zeros((10, HORIZON, 4)), epochs=1, progress_bar=False)
    with pytest.raises(ValueError, match=r"\(N, 20, 3\)"):
        model.fit(np.zeros((10, HORIZON * ACTION_DIM)), epochs=1, progress_bar=False)
    data = np.zeros((10, HORIZON, ACTION_DIM))
    data[3, 4, 1] = np.nan
    with pytest.raises(ValueError, match="non-finite"):
        model.fit(data, epochs=1, progress_bar=False)
    with pytest.raises(ValueError, match="validation_fraction"):
        model.fit(np.zeros((10, HORIZON, ACTION_DIM)), epochs=1, validation_fraction=1.0, progress_bar=False)


@pytest.mark.parametrize("model_class, kwargs", [(BetaVAE, {"beta": 0.005}), (InfoGAN, {"info_weight": 0.1})])
def test_same_seed_same_weights(model_class, kwargs):
    data, _ = sine_ramp_trajectories(120, 6, 2, rng=0)

    def weights(seed: int) -> dict[str, torch.Tensor]:
        model = model_class(6, 2, 2, **kwargs, device="cpu")
        return model.fit(data, epochs=2, batch_size=32, seed=seed, progress_bar=False).state_tensors()

    first, second, other = weights(3), weights(3), weights(4)
    assert first.keys() == second.keys()
    for key in first:
        torch.testing.assert_close(first[key], second[key], rtol=0, atol=0)
    assert any(not torch.equal(first[key], other[key]) for key in first if first[key].is_floating_point())


@pytest.mark.parametrize("model_class, kwargs", [(BetaVAE, {"beta": 0.005}), (InfoGAN, {"info_weight": 0.1})])
def test_the_multi_tensor_adam_trains_the_weights_of_the_per_parameter_one(model_class, kwargs, monkeypatch):
    data, _ = sine_ramp_trajectories(120, 6, 2, rng=0)

    def weights() -> dict[str, torch.Tensor]:
        model = model_class(6, 2, 2, **kwargs, device="cpu")
        return model.fit(data, epochs=3, batch_size=32, seed=5, progress_bar=False).state_tensors()

    foreach = weights()
    adam = torch.optim.Adam
    made = []

    def per_parameter(*args, **kw):
        made.append(kw.pop("foreach"))
        return adam(*args, **kw, foreach=False)

    monkeypatch.setattr(torch.optim, "Adam", per_parameter)
    single = weights()
    assert made and all(made)  # the models asked for the multi-tensor steps
    for key in foreach:
        torch.testing.assert_close(foreach[key], single[key], rtol=0, atol=0)


def test_presets_match_paper_table_1():
    expected_vae = [(2, 0.01), (2, 0.005), (2, 0.001), (3, 0.01), (3, 0.005), (3, 0.001), (6, 0.01), (6, 0.005), (6, 0.001)]
    expected_gan = [(2, 0.1), (2, 1.5), (2, 3.5), (3, 0.1), (3, 1.5), (3, 3.5), (6, 0.1), (6, 1.5), (6, 3.5)]
    for index, (latent_dim, beta) in enumerate(expected_vae, start=1):
        assert PRESETS[f"VAE{index}"] == {"model": "vae", "latent_dim": latent_dim, "beta": beta}
    for index, (latent_dim, info_weight) in enumerate(expected_gan, start=1):
        assert PRESETS[f"GAN{index}"] == {"model": "gan", "latent_dim": latent_dim, "info_weight": info_weight}
    assert len(PRESETS) == 18
    model = make_generator("VAE6", horizon=69, action_dim=7, device="cpu")
    assert isinstance(model, BetaVAE) and (model.latent_dim, model.beta, model.prior) == (3, 0.001, "normal")
    model = make_generator("GAN5", horizon=78, action_dim=7, device="cpu")
    assert isinstance(model, InfoGAN) and (model.latent_dim, model.info_weight, model.prior) == (3, 1.5, "uniform")
    assert model.decode(np.zeros((2, 3))).shape == (2, 78, 7)
    model = make_generator("gan", horizon=5, action_dim=2, latent_dim=4, info_weight=0.5, device="cpu")
    assert (model.latent_dim, model.info_weight) == (4, 0.5)
    with pytest.raises(ValueError, match="beta"):
        make_generator("vae", horizon=5, action_dim=2, latent_dim=2)
    with pytest.raises(ValueError, match="latent_dim"):
        make_generator("VAE1", horizon=5, action_dim=2, latent_dim=3)
    with pytest.raises(ValueError, match="unknown generator"):
        make_generator("VAE10", horizon=5, action_dim=2)


def test_selection_mse_matches_brute_force():
    rng = np.random.default_rng(0)
    generated, reference = rng.normal(size=(7, 4, 3)), rng.normal(size=(11, 4, 3))
    expected = []
    for trajectory in generated:
        distances = [np.sum((trajectory - other) ** 2) for other in reference]
        expected.append(np.mean((trajectory - reference[int(np.argmin(distances))]) ** 2))
    assert selection_mse(generated, reference) == pytest.approx(np.mean(expected), rel=1e-10)
    assert selection_mse(generated, reference, chunk_size=3) == pytest.approx(np.mean(expected), rel=1e-10)
    assert selection_mse(reference[:3], reference) == pytest.approx(0.0, abs=1e-12)


def test_split_and_normalisation_statistics():
    data = np.random.default_rng(0).normal(loc=2.0, size=(50, 4, 3)).astype(np.float32)
    data[:, :, 2] = 5.0  # a joint that never moves
    train, held_out = split_train_validation(data, 0.1, np.random.default_rng(0))
    assert (len(train), len(held_out)) == (45, 5)
    assert sorted(map(bytes, np.concatenate([train, held_out]))) == sorted(map(bytes, data))
    mean, std = normalisation_statistics(train)
    assert mean.shape == std.shape == (4, 3)
    for t in range(4):
        for j in range(2):
            assert mean[t, j] == pytest.approx(np.mean(train[:, t, j], dtype=np.float64), rel=1e-5)
            assert std[t, j] == pytest.approx(np.std(train[:, t, j], dtype=np.float64), rel=1e-5)
    np.testing.assert_array_equal(mean[:, 2], 5.0)
    np.testing.assert_allclose(std[:, 2], MIN_STD, rtol=1e-6)


def test_normalisation_std_floor_is_relative_to_the_largest_std():
    rng = np.random.default_rng(1)
    data = rng.normal(size=(200, 3, 2)) * np.array([[1.0, 0.01], [5.0, 0.2], [0.5, 2.0]])  # per-entry spreads
    mean, std = normalisation_statistics(data, std_floor=0.1)
    raw = data.std(axis=0)  # brute force: each entry's std, then max(std, 0.1 * largest)
    np.testing.assert_allclose(mean, data.mean(axis=0), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(std, np.maximum(raw, 0.1 * raw.max()), rtol=1e-5)
    assert std[0, 1] == pytest.approx(0.1 * raw.max(), rel=1e-5) and std[1, 0] == pytest.approx(raw[1, 0], rel=1e-5)
    with pytest.raises(ValueError, match="std_floor"):
        normalisation_statistics(data, std_floor=1.5)
    with pytest.raises(ValueError, match="std_floor"):
        BetaVAE(3, 2, 2, beta=0.01, std_floor=-0.1)


def test_train_generator_and_cli_write_loadable_models(tmp_path, capsys):
    data, _ = sine_ramp_trajectories(100, 6, 2, rng=0)
    npy = tmp_path / "demos.npy"
    np.save(npy, data)
    out = tmp_path / "gan.pt"
    code = cli_main(
        [
            "train-generator",
            "--data",
            str(npy),
            "--preset",
            "GAN2",
            "--epochs",
            "2",
            "--batch-size",
            "32",
            "--no-progress-bar",
            "--out",
            str(out),
            "--tensorboard-log",
            str(tmp_path / "tb"),
        ]
    )
    assert code == 0 and "InfoGAN" in capsys.readouterr().out
    model = load(out)
    assert isinstance(model, InfoGAN) and (model.latent_dim, model.info_weight, model.horizon) == (2, 1.5, 6)
    assert any((tmp_path / "tb").iterdir())
    npz = tmp_path / "demos.npz"
    np.savez(npz, actions=data)
    vae = train_generator(npz, latent_dim=3, beta=0.001, epochs=1, batch_size=32, out=tmp_path / "vae.pt")
    assert (
        load(tmp_path / "vae.pt").config()
        == vae.config()
        == {"horizon": 6, "action_dim": 2, "latent_dim": 3, "std_floor": 0.05, "beta": 0.001}
    )
    assert (
        cli_main(
            [
                "train-generator",
                "--data",
                str(npz),
                "--preset",
                "VAE1",
                "--std-floor",
                "0.2",
                "--epochs",
                "1",
                "--batch-size",
                "32",
                "--no-progress-bar",
                "--out",
                str(tmp_path / "vae_floor.pt"),
            ]
        )
        == 0
    )
    floored = load(tmp_path / "vae_floor.pt")
    assert floored.std_floor == 0.2
    assert float(floored.action_std.min()) >= 0.2 * float(floored.action_std.max()) * (1 - 1e-6)
    assert cli_main(["train-generator", "--data", str(npy), "--model", "vae", "--out", str(tmp_path / "v.pt")]) == 2
    assert "needs" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (("--data", "missing.npy"), "argument --data: 'missing.npy' does not exist"),
        (("--lr", "-1"), "argument --lr: must be a finite number > 0, got -1.0"),
        (("--lr", "inf"), "argument --lr: must be a finite number > 0, got inf"),
        (("--epochs", "0"), "argument --epochs: must be an integer >= 1, got 0"),
        (("--min-steps", "-1"), "argument --min-steps: must be an integer >= 0, got -1"),
        (("--selection", "best"), "argument --selection: invalid choice: 'best'"),
        (("--preset", "GAN1", "--selection", "reconstruction"), "selection='reconstruction' needs a model with an encoder"),
        (("--seed", "-1"), "argument --seed: must be an integer between 0 and 4294967295, got -1"),
        (("--device", "bogus"), "argument --device: must be 'auto' or a torch device"),
        (("--out", "."), "argument --out: '.' is a folder; expected a file name"),
    ],
)
def test_train_generator_cli_checks_arguments_first(tmp_path, cli, monkeypatch, args, message):
    monkeypatch.chdir(tmp_path)
    np.save("demos.npy", np.zeros((10, 4, 2), dtype=np.float32))
    argv = dict(zip(args[::2], args[1::2], strict=True))
    argv = {"--data": "demos.npy", "--epochs": "1", "--out": "vae.pt", **argv}
    code, _, err = cli("train-generator", *(item for pair in argv.items() for item in pair))
    assert code == 2 and message in err and not (tmp_path / "vae.pt").exists()


def test_train_generator_checks_arguments_before_training(tmp_path):
    data = np.zeros((10, 4, 2), dtype=np.float32)
    (tmp_path / "folder").mkdir()
    for kwargs, message in (
        ({"epochs": -1}, "epochs must be an integer >= 1, got -1"),
        ({"batch_size": 2.5}, r"batch_size must be an integer >= 1, got 2.5 \(float\)"),
        ({"lr": float("nan")}, "lr must be a finite number > 0"),
        ({"out": tmp_path / "folder"}, "is a folder; expected a file name"),
        ({"min_steps": -1}, "min_steps must be an integer >= 0, got -1"),
        ({"selection": "best"}, "selection must be one of"),
        ({"preset": "GAN1", "selection": "reconstruction"}, "InfoGAN has none"),
    ):
        with pytest.raises(ValueError, match=message):
            train_generator(data, **kwargs)


def test_train_generator_refuses_an_output_that_is_one_of_its_inputs(tmp_path, cli):
    npy = tmp_path / "demos.npy"
    np.save(npy, np.ones((10, 4, 2), dtype=np.float32))
    dataset = tmp_path / "dataset"
    dataset.mkdir()
    (dataset / "genrl_episodes.npz").write_bytes(b"the dataset's own copy")
    for data, out, message in (
        (npy, npy, "is the data file"),
        (str(npy), tmp_path / "." / "demos.npy", "is the data file"),
        (dataset, dataset / "genrl_episodes.npz", "is inside the dataset"),
        (dataset, dataset / "new.pt", "is inside the dataset"),
    ):
        with pytest.raises(ValueError, match=message):
            train_generator(data, epochs=1, out=out)
    code, _, err = cli("train-generator", "--data", str(npy), "--epochs", "1", "--out", str(npy))
    assert code == 2 and "would overwrite its training data" in err
    np.testing.assert_array_equal(np.load(npy), np.ones((10, 4, 2)))  # the inputs are untouched
    assert (dataset / "genrl_episodes.npz").read_bytes() == b"the dataset's own copy" and len(list(dataset.iterdir())) == 1


def test_infogan_noise_is_fixed_at_decode(tmp_path):
    data, _ = sine_ramp_trajectories(80, 6, 2, rng=0)
    model = InfoGAN(6, 2, 2, info_weight=1.0, noise_dim=3, device="cpu").fit(
        data, epochs=1, batch_size=32, seed=0, progress_bar=False
    )
    assert model.networks["generator"][0].in_features == 5
    alpha = model.sample_prior(4, rng=0)
    with torch.no_grad():
        expected = model.networks["generator"](torch.cat([torch.as_tensor(alpha), torch.zeros(4, 3)], dim=1))
    expected = (expected.view(4, 6, 2) * model.action_std + model.action_mean).numpy()
    np.testing.assert_allclose(model.decode(alpha), expected, rtol=1e-6)
    model.save(tmp_path / "gan.pt")
    restored = load(tmp_path / "gan.pt", device="cpu")  # the same device: GPU kernels may differ in the last bit
    assert restored.noise_dim == 3
    np.testing.assert_array_equal(restored.decode(alpha), model.decode(alpha))


def test_corrupted_weights_are_refused_on_load(vae, tmp_path):
    path = tmp_path / "vae.pt"
    vae.save(path)
    data = bytearray(path.read_bytes())
    weight = vae.decoder[-1].weight.detach().cpu().numpy().tobytes()  # the largest tensor, stored uncompressed
    start = bytes(data).find(weight[:256])
    assert start > 0
    data[start + 64 : start + 128] = bytes(b ^ 0x5A for b in data[start + 64 : start + 128])  # 64 bytes flipped
    path.write_bytes(bytes(data))
    with pytest.raises(ValueError, match="checksum") as error:
        load(path)
    assert str(path) in str(error.value)


def test_file_without_checksum_is_refused_naming_the_file(vae, tmp_path):
    path = tmp_path / "old.pt"
    vae.save(path)
    payload = torch.load(path, weights_only=True)
    del payload["sha256"]
    payload["format_version"] = 1
    torch.save(payload, path)
    with pytest.raises(ValueError, match="predates") as error:
        load(path)
    assert str(path) in str(error.value)


def test_diverged_training_is_not_saved(family, tmp_path, cli):
    diverged = BetaVAE(HORIZON, ACTION_DIM, 2, beta=0.01, device="cpu").fit(
        family[0][:300], epochs=4, seed=0, lr=1e6, progress_bar=False, eval_every=2
    )
    assert diverged.best_epoch is None  # every selection MSE was nan
    with pytest.raises(ValueError, match="no checkpoint was selected"):
        diverged.save(tmp_path / "nan.pt")
    diverged.best_epoch = 4
    with pytest.raises(ValueError, match="non-finite"):
        diverged.save(tmp_path / "nan.pt")
    assert not (tmp_path / "nan.pt").exists()
    npy = tmp_path / "demos.npy"
    np.save(npy, family[0][:300])
    for option, value in (("--lr", "1e6"), ("--lr", "inf"), ("--beta", "inf")):
        out = tmp_path / f"cli{option}{value}.pt"
        code, _, err = cli(
            "train-generator",
            "--data",
            npy,
            "--model",
            "vae",
            "--latent-dim",
            2,
            option,
            value,
            "--epochs",
            2,
            "--batch-size",
            64,
            "--no-progress-bar",
            "--out",
            out,
        )
        assert code == 2 and not out.exists(), (option, value)
        assert err.strip(), (option, value)


def test_interrupted_save_leaves_no_partial_file(vae, tmp_path, monkeypatch):
    from sb3_genrl.generative import serialization

    path = tmp_path / "vae.pt"
    real_save = torch.save

    def killed_save(payload, file):
        real_save(payload, file)
        with open(file, "r+b") as handle:
            handle.truncate(5000)  # what a kill during the write leaves behind
        raise KeyboardInterrupt

    monkeypatch.setattr(serialization.torch, "save", killed_save)
    with pytest.raises(KeyboardInterrupt):
        vae.save(path)
    assert list(tmp_path.iterdir()) == []
    monkeypatch.setattr(serialization.torch, "save", real_save)
    vae.save(path)
    before = path.read_bytes()
    monkeypatch.setattr(serialization.torch, "save", killed_save)
    with pytest.raises(KeyboardInterrupt):
        vae.save(path)
    assert list(tmp_path.iterdir()) == [path] and path.read_bytes() == before


def test_fit_keeps_the_device_the_model_was_built_on(monkeypatch):
    """A model built on the CPU trains on the CPU even where a GPU is present (fit's device defaults to the model's)."""
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)  # what "auto" would pick on a GPU machine
    data, _ = sine_ramp_trajectories(64, 6, 2, rng=0)
    model = BetaVAE(6, 2, 2, beta=0.01, device="cpu").fit(data, epochs=1, batch_size=32, seed=0, progress_bar=False)
    assert model.device.type == "cpu" and model.action_mean.device.type == "cpu"
    assert all(p.device.type == "cpu" for p in model.networks.parameters())


def test_path_error_matches_a_brute_force_running_sum(tmp_path):
    """BetaVAE's path term: the running sum of the raw per-step errors, per joint in units of its time-averaged
    normalisation std, over sqrt(T), squared and averaged; saved with the model, absent from eq. 9's models' files."""
    horizon, joints = 6, 3
    rng = np.random.default_rng(0)
    vae = BetaVAE(horizon, joints, 2, beta=0.01, path_weight=2.5, device="cpu")
    vae.action_std = torch.as_tensor(rng.uniform(0.5, 2.0, (horizon, joints)), dtype=torch.float32)
    reconstruction, batch = (torch.as_tensor(rng.normal(size=(4, horizon * joints)), dtype=torch.float32) for _ in range(2))
    raw = (reconstruction - batch).numpy().reshape(4, horizon, joints) * vae.action_std.numpy()
    sigma = vae.action_std.numpy().mean(axis=0)
    expected = np.mean(
        [
            (sum(raw[b, s, j] for s in range(t + 1)) / (sigma[j] * np.sqrt(horizon))) ** 2
            for b in range(4)
            for t in range(horizon)
            for j in range(joints)
        ]
    )
    np.testing.assert_allclose(vae.path_error(reconstruction, batch).item(), expected, rtol=1e-5)
    assert vae.config()["path_weight"] == 2.5 and "path_weight" not in BetaVAE(horizon, joints, 2, beta=0.01).config()
    fetch = make_generator("VAE-FETCH", horizon=horizon, action_dim=joints, device="cpu")
    assert (fetch.latent_dim, fetch.beta, fetch.path_weight) == (10, 0.001, 1.0)
    with pytest.raises(ValueError, match="path_weight"):
        BetaVAE(horizon, joints, 2, beta=0.01, path_weight=-1.0)


def test_path_weight_trains_a_model_that_saves_and_loads_with_it(family, tmp_path):
    trajectories, _ = family
    models = [
        BetaVAE(trajectories.shape[1], trajectories.shape[2], 2, beta=0.01, path_weight=weight, device="cpu").fit(
            trajectories[:200], epochs=3, seed=0, eval_every=3
        )
        for weight in (0.0, 4.0)
    ]
    assert "path" in models[1].history[-1] and "path" not in models[0].history[-1]
    latents = np.zeros((1, 2), dtype=np.float32)
    assert not np.allclose(models[0].decode(latents), models[1].decode(latents))  # the term changes the training
    models[1].save(tmp_path / "path.pt")
    loaded = load(tmp_path / "path.pt", device="cpu")
    assert loaded.path_weight == 4.0
    np.testing.assert_array_equal(loaded.decode(latents), models[1].decode(latents))


def test_reconstruction_selection_keeps_the_checkpoint_that_reconstructs_the_held_out_split_best(family, tmp_path):
    train = family[0][:400]
    model = BetaVAE(HORIZON, ACTION_DIM, 2, beta=0.01, device="cpu").fit(
        train, epochs=20, seed=3, progress_bar=False, eval_every=2, selection="reconstruction"
    )
    assert model.selection == "reconstruction"
    errors = {entry["epoch"]: entry["selection_mse"] for entry in model.history}
    assert model.best_epoch == min(errors, key=errors.get)
    # the held-out split fit() draws first from its seed, decoded from the posterior means by hand (the brute force)
    _, held_out = split_train_validation(train, 0.1, np.random.default_rng(3))
    with torch.no_grad():
        normalised = model.normalise(torch.as_tensor(held_out))
        means, _ = model.networks["encoder"](normalised)
        decoded = model.denormalise(model.networks["decoder"](means).reshape(held_out.shape))
    brute_force = float(((decoded.double() - torch.as_tensor(held_out).double()) ** 2).mean())
    assert model.reconstruction_mse(held_out) == pytest.approx(brute_force, rel=1e-5)
    assert errors[model.best_epoch] == pytest.approx(brute_force, rel=1e-5)  # the restored weights are the best's
    # the paper's selection scores other errors (generated trajectories against their nearest held-out ones)
    paper = BetaVAE(HORIZON, ACTION_DIM, 2, beta=0.01, device="cpu").fit(
        train, epochs=20, seed=3, progress_bar=False, eval_every=2
    )
    assert paper.selection == "prior" and [entry["selection_mse"] for entry in paper.history] != list(errors.values())
    # the choice is saved with the model; a file written before it existed reads as the paper's
    model.save(tmp_path / "vae.pt")
    assert load(tmp_path / "vae.pt").selection == "reconstruction"
    with pytest.raises(ValueError, match="InfoGAN has none"):
        InfoGAN(HORIZON, ACTION_DIM, 2, info_weight=1.5, device="cpu").fit(train, epochs=1, selection="reconstruction")


def test_min_steps_raises_the_epochs_of_a_small_dataset(family, monkeypatch):
    steps = []
    original = BetaVAE._train_step

    def counted(self, *args, **kwargs):
        steps.append(1)
        return original(self, *args, **kwargs)

    monkeypatch.setattr(BetaVAE, "_train_step", counted)
    # 100 trajectories: 90 to train on, in minibatches of 32, 32 and 26: 3 steps an epoch
    data = family[0][:100]
    model = BetaVAE(HORIZON, ACTION_DIM, 2, beta=0.01, device="cpu")
    model.fit(data, epochs=2, batch_size=32, seed=0, progress_bar=False, eval_every=1, min_steps=31)
    assert len(steps) == 33 and model.history[-1]["epoch"] == 11  # ceil(31 / 3) epochs
    steps.clear()
    model.fit(data, epochs=12, batch_size=32, seed=0, progress_bar=False, eval_every=1, min_steps=31)
    assert len(steps) == 36 and model.history[-1]["epoch"] == 12  # enough epochs already: as given
    steps.clear()
    model.fit(data, epochs=2, batch_size=32, seed=0, progress_bar=False, eval_every=1)
    assert len(steps) == 6


@pytest.mark.parametrize(("n", "batch_size"), [(523, 256), (270, 256), (90, 32), (512, 256), (7, 3), (1, 4)])
def test_even_minibatches_cover_the_permutation_in_as_many_batches_of_nearly_equal_sizes(n, batch_size):
    permutation = np.random.default_rng(0).permutation(n)
    plain = minibatch_indices(n, batch_size, permutation)
    even = minibatch_indices(n, batch_size, permutation, even=True)
    sizes = [len(batch) for batch in even]
    if n < 2:
        assert plain == even == []  # batch norm needs two
        return
    assert len(even) == -(-n // batch_size) and max(sizes) <= batch_size and max(sizes) - min(sizes) <= 1
    np.testing.assert_array_equal(np.concatenate(even), permutation)  # every index once, in the permutation's order
    # the plain split: full batches and the remainder (523 = 256 + 256 + 11, against 175 + 174 + 174), a remainder
    # of one dropped (7 = 3 + 3 + 1, against 3 + 2 + 2)
    remainder = n % batch_size
    assert [len(batch) for batch in plain] == [batch_size] * (n // batch_size) + ([remainder] if remainder > 1 else [])


def test_even_batches_train_on_every_trajectory_in_batches_of_nearly_equal_sizes(family, monkeypatch):
    sizes = []
    original = BetaVAE._train_step

    def recorded(self, batch, *args, **kwargs):
        sizes.append(len(batch))
        return original(self, batch, *args, **kwargs)

    monkeypatch.setattr(BetaVAE, "_train_step", recorded)
    model = BetaVAE(HORIZON, ACTION_DIM, 2, beta=0.01, device="cpu")
    model.fit(family[0][:100], epochs=2, batch_size=32, seed=0, progress_bar=False, even_batches=True)
    assert sizes == [30, 30, 30] * 2  # 90 training trajectories: 3 batches of 30, against 32 + 32 + 26


def test_genrl_train_generator_refuses_an_existing_out_without_overwrite(tmp_path, cli):
    npy = tmp_path / "demos.npy"
    np.save(npy, sine_ramp_trajectories(64, 6, 2, rng=0)[0])
    args = ("train-generator", "--data", npy, "--preset", "VAE1", "--epochs", 1, "--batch-size", 32, "--no-progress-bar")
    out = tmp_path / "vae.pt"
    assert cli(*args, "--out", out)[0] == 0
    first = out.read_bytes()
    code, _, err = cli(*args, "--seed", 1, "--out", out)
    assert code == 2 and "already exists; pass --overwrite" in err and out.read_bytes() == first
    assert cli(*args, "--seed", 1, "--out", out, "--overwrite")[0] == 0 and out.read_bytes() != first
