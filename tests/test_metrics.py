"""Tests of sb3_genrl.metrics against brute-force references on small sets."""

from __future__ import annotations

import csv
import importlib
import math

import gymnasium as gym
import numpy as np
import pytest
from scipy.spatial.distance import cdist
from scipy.stats import norm

from sb3_genrl.generative.base import TrajectoryGenerator
from sb3_genrl.metrics import (
    correlation_table,
    default_intervention_values,
    dwpr,
    evaluate_generators,
    precision_recall,
)

# The module, which the package's function of the same name hides.
precision_recall_module = importlib.import_module("sb3_genrl.metrics.precision_recall")


def brute_force(real: np.ndarray, generated: np.ndarray, k: int) -> tuple[float, float, np.ndarray, np.ndarray]:
    """Reference: full float64 distance matrices, own index excluded, ties inside (<=)."""
    real = real.reshape(len(real), -1).astype(np.float64)
    generated = generated.reshape(len(generated), -1).astype(np.float64)
    radii = []
    for points in (real, generated):
        distances = cdist(points, points)
        np.fill_diagonal(distances, np.inf)
        radii.append(np.sort(distances, axis=1)[:, k - 1])
    cross = cdist(real, generated)
    precision = (cross <= radii[0][:, None]).any(0).mean()
    recall = (cross <= radii[1][None, :]).any(1).mean()
    return float(precision), float(recall), radii[0], radii[1]


class LinearGenerator(TrajectoryGenerator):
    """tau = reshape(alpha @ weights): each latent dimension moves the trajectory along one row of ``weights``."""

    def __init__(self, weights: np.ndarray, horizon: int, action_dim: int, prior: str = "normal") -> None:
        super().__init__(horizon=horizon, action_dim=action_dim, latent_dim=weights.shape[0], prior=prior)
        self.weights = np.asarray(weights, dtype=np.float32)

    def decode(self, alpha: np.ndarray) -> np.ndarray:
        alpha = self.check_latent(alpha)
        return (alpha @ self.weights).reshape(len(alpha), self.horizon, self.action_dim)

    def save(self, path: str) -> None:
        raise NotImplementedError


def two_factor_generator(ignored_dims: int = 1) -> LinearGenerator:
    """Dimension 0 alone sets the first half of the trajectory, dimension 1 the second half, others do nothing."""
    horizon, action_dim = 4, 2
    weights = np.zeros((2 + ignored_dims, horizon * action_dim), dtype=np.float32)
    weights[0, :4] = 1.0
    weights[1, 4:] = 1.0
    return LinearGenerator(weights, horizon, action_dim)


def grid_points(rng: np.random.Generator, n: int, dim: int) -> np.ndarray:
    """Integer points on a small grid: exact duplicates and exactly tied distances."""
    return rng.integers(0, 3, size=(n, dim)).astype(np.float32)


POINT_SETS = ("gaussian", "grid", "offset_grid", "trajectories")


def point_sets(kind: str, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Real and generated sets of one of :data:`POINT_SETS`' kinds, each a hard case of its own."""
    if kind == "gaussian":
        return rng.normal(size=(70, 6)), rng.normal(0.4, 1.2, size=(45, 6))
    if kind == "grid":
        return grid_points(rng, 60, 3), grid_points(rng, 50, 3)
    if kind == "offset_grid":  # exact ties that float32 values far from the origin cannot resolve
        return (
            1000.0 + grid_points(rng, 60, 4).astype(np.float64) / 4,
            1000.0 + grid_points(rng, 50, 4).astype(np.float64) / 4,
        )
    # (N, T, M) with a large common offset, where float32 cancellation is worst
    return 100.0 + rng.normal(size=(50, 4, 3)).astype(np.float32), 100.0 + rng.normal(size=(40, 4, 3)).astype(np.float32)


@pytest.mark.parametrize("kind", POINT_SETS)
@pytest.mark.parametrize("k", [1, 3, 5])
def test_precision_recall_matches_brute_force(kind: str, k: int) -> None:
    real, generated = point_sets(kind, np.random.default_rng(k))
    expected = brute_force(real, generated, k)
    for batch_size in (1, 4, 17, None):
        result = precision_recall(real, generated, k, batch_size=batch_size, device="cpu", return_radii=True)
        assert (result.precision, result.recall) == expected[:2], (batch_size, result)
        np.testing.assert_allclose(result.real_radii, expected[2], rtol=1e-12, atol=0)
        np.testing.assert_allclose(result.generated_radii, expected[3], rtol=1e-12, atol=0)
        assert (result.k, result.num_real, result.num_generated) == (k, len(real), len(generated))


def test_duplicates_count_as_neighbours() -> None:
    # Every real point appears 3 times: with k = 2 the radii are 0 and only exact copies are inside.
    base = np.array([[0.0, 0.0], [5.0, 0.0], [0.0, 5.0]])
    real = np.repeat(base, 3, axis=0)
    generated = np.array([[0.0, 0.0], [5.0, 0.0], [0.1, 0.0], [2.0, 2.0]])
    result = precision_recall(real, generated, k=2, batch_size=2, device="cpu", return_radii=True)
    np.testing.assert_array_equal(result.real_radii, np.zeros(9))
    assert result.precision == 0.5
    assert (result.precision, result.recall) == brute_force(real, generated, 2)[:2]


def test_identical_and_disjoint_sets() -> None:
    rng = np.random.default_rng(0)
    points = rng.normal(size=(40, 5))
    same = precision_recall(points, points.copy(), k=3, batch_size=8, device="cpu")
    assert same.precision == same.recall == 1.0
    far = precision_recall(points, points + 1000.0, k=3, device="cpu")
    assert far.precision == far.recall == 0.0


def test_precision_recall_rejects_bad_inputs() -> None:
    points = np.zeros((10, 3))
    with pytest.raises(ValueError, match="same size"):
        precision_recall(points, np.zeros((10, 4)))
    with pytest.raises(ValueError, match="k must be a positive"):
        precision_recall(points, points, k=0)
    with pytest.raises(ValueError, match="smaller than both"):
        precision_recall(points, np.zeros((3, 3)), k=3)
    bad = points.copy()
    bad[2, 1] = np.nan
    with pytest.raises(ValueError, match="non-finite"):
        precision_recall(points, bad)
    with pytest.raises(ValueError, match="shape"):
        precision_recall(np.zeros(10), points)
    with pytest.raises(ValueError, match="batch_size"):
        precision_recall(points, points, batch_size=0)


def test_default_intervention_values() -> None:
    np.testing.assert_allclose(default_intervention_values("normal", 5), norm.ppf([0.1, 0.3, 0.5, 0.7, 0.9]), rtol=1e-6)
    np.testing.assert_allclose(default_intervention_values("uniform", 5), [-0.8, -0.4, 0.0, 0.4, 0.8], atol=1e-7)
    with pytest.raises(ValueError):
        default_intervention_values("normal", 0)


def test_dwpr_separates_decisive_and_ignored_dimensions() -> None:
    generator = two_factor_generator(ignored_dims=1)
    result = dwpr(generator, n=150, interventions=5, k=3, seed=0, device="cpu")
    assert result.delta.shape == (3,)
    np.testing.assert_allclose(result.delta, result.precision - result.recall)
    # Dimensions 0 and 1 each fix one half of the trajectory: realistic but covering little of the reference.
    assert result.delta[0] > 0.4 and result.delta[1] > 0.4
    # Dimension 2 is ignored: fixing it changes nothing, recall stays high and delta is near 0.
    assert abs(result.delta[2]) < 0.1 and result.recall[2] > 0.8
    assert result.delta_1 == pytest.approx(result.delta[:2].max())
    assert result.delta_2 == pytest.approx(result.delta[:2].min())
    assert result.mean_delta == pytest.approx((result.delta_1 + result.delta_2) / 2)
    np.testing.assert_allclose(result.intervention_values, default_intervention_values("normal", 5))
    again = dwpr(generator, n=150, interventions=5, k=3, seed=0, device="cpu")
    np.testing.assert_array_equal(again.delta, result.delta)


def test_dwpr_is_unchanged_when_trajectories_are_scaled_by_a_power_of_two() -> None:
    # Scaling by 2**70 (about 1e21) is exact and keeps every distance comparison: the same precision and recall.
    generator = two_factor_generator(ignored_dims=1)
    scaled = LinearGenerator(generator.weights * np.float32(2.0**70), generator.horizon, generator.action_dim)
    result, large = (dwpr(g, n=100, interventions=3, k=3, seed=0, device="cpu") for g in (generator, scaled))
    np.testing.assert_array_equal(large.precision, result.precision)
    np.testing.assert_array_equal(large.recall, result.recall)


def test_dwpr_single_dimension_and_explicit_values() -> None:
    generator = LinearGenerator(np.ones((1, 6), dtype=np.float32), horizon=3, action_dim=2, prior="uniform")
    result = dwpr(generator, n=40, k=2, seed=1, intervention_values=[-0.5, 0.5], device="cpu")
    assert result.delta_2 == 0.0 and result.mean_delta == pytest.approx(result.delta_1 / 2)
    np.testing.assert_allclose(result.intervention_values, [-0.5, 0.5])
    with pytest.raises(ValueError):
        dwpr(generator, n=0)


def test_correlation_table_against_numpy() -> None:
    rng = np.random.default_rng(3)
    records = []
    for index in range(8):
        kind = "VAE" if index % 2 == 0 else "GAN"
        records.append(
            {
                "model": f"{kind}{index}",
                "type": kind,
                "precision": rng.uniform(),
                "recall": rng.uniform(),
                "delta_1": rng.uniform(),
                "mean_delta": 0.5,
                "score": rng.normal(),
            }
        )
    table = correlation_table(records, measure_names=["precision", "recall", "mean_delta"])
    assert [row.group for row in table.rows[::3]] == ["VAE", "GAN", "ALL"]
    for group in ("VAE", "GAN", "ALL"):
        members = [r for r in records if group == "ALL" or r["type"] == group]
        for name in ("precision", "recall"):
            x = [r[name] for r in members]
            y = [r["score"] for r in members]
            row = table.get(group, name)
            assert row.pearson_r == pytest.approx(np.corrcoef(x, y)[0, 1], abs=1e-12)
            assert row.num_models == len(members)
    constant = table.get("ALL", "mean_delta")
    assert math.isnan(constant.pearson_r) and "constant" in constant.note
    # Known values: x = 1..5, y = (2, 4, 5, 4, 5) has R = sqrt(0.6) and, with t = 2.1213 on 3 degrees of freedom,
    # a two-sided p-value of 0.1240.
    x, y = [1, 2, 3, 4, 5], [2, 4, 5, 4, 5]
    row = correlation_table({f"m{i}": {"recall": x[i]} for i in range(5)}, {f"m{i}": y[i] for i in range(5)}).rows[0]
    assert (row.group, row.measure, row.num_models) == ("ALL", "recall", 5)
    assert row.pearson_r == pytest.approx(math.sqrt(0.6), abs=1e-12)
    assert row.p_value == pytest.approx(0.1240, abs=1e-4)


def test_correlation_table_few_models_and_rendering(tmp_path) -> None:
    records = [
        {"model": "VAE1", "type": "VAE", "recall": 0.1, "score": 1.0},
        {"model": "VAE2", "type": "VAE", "recall": 0.4, "score": 3.0},
        {"model": "GAN1", "type": "GAN", "recall": 0.3, "score": 2.0},
        {"model": "GAN2", "type": "GAN", "recall": float("nan"), "score": 2.5},
    ]
    table = correlation_table(records)
    vae = table.get("VAE", "recall")
    assert math.isnan(vae.pearson_r) and "fewer than 3" in vae.note
    assert "GAN2" in table.get("ALL", "recall").note and table.get("ALL", "recall").num_models == 3
    path = tmp_path / "table.csv"
    table.to_csv(path)
    with open(path) as file:
        rows = list(csv.DictReader(file))
    for row, expected in zip(rows, table.rows, strict=True):
        for key, value in (("pearson_r", expected.pearson_r), ("p_value", expected.p_value)):
            assert float(row[key]) == value or (math.isnan(value) and math.isnan(float(row[key])))
        assert (row["group"], row["measure"], int(row["num_models"])) == (
            expected.group,
            expected.measure,
            expected.num_models,
        )
    markdown = table.to_markdown(digits=4)
    lines = markdown.strip().splitlines()[2:]
    assert len(lines) == len(table.rows)
    for line, expected in zip(lines, table.rows, strict=True):
        cells = [cell.strip() for cell in line.strip("|").split("|")]
        assert cells[:3] == [expected.group, expected.measure, str(expected.num_models)]
        for cell, value in zip(
            [cells[i] for i in (3, 5, 6, 8)],
            (expected.pearson_r, expected.p_value, expected.spearman_rho, expected.spearman_p),
            strict=True,
        ):
            assert (cell == "nan" and math.isnan(value)) or float(cell) == pytest.approx(value, abs=5e-5)
    with pytest.raises(ValueError, match="no 'score'"):
        correlation_table([{"model": "x", "recall": 1.0}])


def brute_force_bootstrap(x, y, resamples: int, seed: int):
    """Reference: one resample at a time with scipy's coefficients, the documented draw of the resamples."""
    from scipy.stats import pearsonr, spearmanr

    x, y = np.asarray(x, float), np.asarray(y, float)
    index = np.random.default_rng(seed).integers(0, len(x), size=(resamples, len(x)))
    r, rho = [], []
    for i in index:
        if np.ptp(x[i]) > 0 and np.ptp(y[i]) > 0:
            r.append(pearsonr(x[i], y[i]).statistic)
            rho.append(spearmanr(x[i], y[i]).statistic)
    return np.percentile(r, [2.5, 97.5]), np.percentile(rho, [2.5, 97.5]), len(r)


def test_bootstrap_intervals_equal_a_loop_over_resamples_and_scipy_bootstrap() -> None:
    from scipy.stats import bootstrap, spearmanr

    from sb3_genrl.metrics.bootstrap import bootstrap_correlations

    rng = np.random.default_rng(1)
    x = np.array([0.1, 0.1, 0.5, 0.5, 0.9])  # ties: exact duplicates in many resamples, constant ones too
    y = x + rng.normal(0, 0.3, size=len(x))
    pearson_ci, spearman_ci = bootstrap_correlations(x, y, resamples=400, seed=5)
    expected_r, expected_rho, defined = brute_force_bootstrap(x, y, 400, 5)
    assert 0 < 400 - defined and pearson_ci.defined == spearman_ci.defined == defined and pearson_ci.resamples == 400
    np.testing.assert_allclose([pearson_ci.low, pearson_ci.high], expected_r, atol=1e-12)
    np.testing.assert_allclose([spearman_ci.low, spearman_ci.high], expected_rho, atol=1e-12)
    # Against scipy's own percentile bootstrap (other resamples): the same interval up to resampling noise.
    x, y = rng.normal(size=15), rng.normal(size=15)
    y = y + x
    pearson_ci, spearman_ci = bootstrap_correlations(x, y, resamples=2000, seed=0)
    for statistic, ours in (
        (lambda a, b: np.corrcoef(a, b)[0, 1], pearson_ci),
        (lambda a, b: spearmanr(a, b).statistic, spearman_ci),
    ):
        theirs = bootstrap(
            (x, y),
            statistic,
            paired=True,
            vectorized=False,
            n_resamples=2000,
            method="percentile",
            rng=np.random.default_rng(1),
        ).confidence_interval
        assert abs(ours.low - theirs.low) < 0.05 and abs(ours.high - theirs.high) < 0.05


def test_correlation_rows_hold_spearman_and_the_bootstrap_intervals(tmp_path) -> None:
    from scipy.stats import spearmanr

    rng = np.random.default_rng(2)
    records = [{"model": f"m{i}", "recall": rng.uniform(), "score": rng.normal()} for i in range(7)]
    row = correlation_table(records, measure_names=["recall"], resamples=300, seed=3).rows[0]
    x, y = [r["recall"] for r in records], [r["score"] for r in records]
    assert row.spearman_rho == pytest.approx(spearmanr(x, y).statistic, abs=1e-12)
    expected_r, expected_rho, _ = brute_force_bootstrap(x, y, 300, 3)
    np.testing.assert_allclose(
        [row.pearson_low, row.pearson_high, row.spearman_low, row.spearman_high], [*expected_r, *expected_rho], atol=1e-12
    )
    assert row.pearson_low <= row.pearson_r <= row.pearson_high and row.resamples == 300
    table = correlation_table(records, measure_names=["recall"], resamples=300, seed=3)
    table.to_csv(tmp_path / "t.csv")
    with open(tmp_path / "t.csv") as file:
        written = next(csv.DictReader(file))
    assert float(written["spearman_low"]) == row.spearman_low and written["resamples"] == "300"
    assert f"[{row.pearson_low:.2f}, {row.pearson_high:.2f}]" in table.to_markdown()


def test_evaluate_generators_writes_table_and_plots(tmp_path) -> None:
    generators = {"A": two_factor_generator(ignored_dims=0), "B": two_factor_generator(ignored_dims=1)}
    real = generators["A"].decode(generators["A"].sample_prior(300, 5))
    np.save(tmp_path / "real.npy", real)
    out = tmp_path / "eval"
    evaluations = evaluate_generators(
        generators, tmp_path / "real.npy", n=200, k=3, dwpr_n=40, interventions=3, seed=0, out_dir=out, device="cpu"
    )
    assert [evaluation.name for evaluation in evaluations] == ["A", "B"]
    for name in ("results.csv", "results.md", "results.json", "precision_recall.png", "disentanglement.png"):
        assert (out / name).stat().st_size > 0
    with open(out / "results.csv") as file:
        rows = list(csv.DictReader(file))
    assert [row["model"] for row in rows] == ["A", "B"]
    assert float(rows[0]["precision"]) == evaluations[0].precision_recall.precision
    assert float(rows[1]["mean_delta"]) == evaluations[1].dwpr.mean_delta
    assert float(rows[1]["coverage"]) == evaluations[1].density_coverage.coverage
    assert evaluations[0].precision_recall.precision > 0.8  # same distribution as the real set
    with pytest.raises(ValueError, match="horizon"):
        evaluate_generators([LinearGenerator(np.ones((1, 3)), 3, 1)], real, n=50, dwpr_n=10, out_dir=out)


def test_cli_evaluate(tmp_path, cli) -> None:
    from sb3_genrl.generative import make_generator

    generator = make_generator("vae", horizon=4, action_dim=2, latent_dim=2, beta=1.0, device="cpu")
    generator.save(str(tmp_path / "vae.pt"))
    np.save(tmp_path / "real.npy", np.random.default_rng(0).normal(size=(120, 4, 2)).astype(np.float32))
    args = [
        "evaluate",
        tmp_path / "vae.pt",
        "--data",
        tmp_path / "real.npy",
        "--out",
        tmp_path / "out",
        "--dwpr-n",
        20,
        "--k",
        3,
        "--seed",
        0,
        "--device",
        "cpu",
    ]
    code, printed, err = cli(*args, "--n", 100)
    assert code == 0, err
    with open(tmp_path / "out" / "results.csv") as file:
        row = next(csv.DictReader(file))
    cells = [f"{float(row[key]):.3f}" for key in ("precision", "recall", "density", "coverage", "delta_1", "mean_delta")]
    assert f"| 1 | vae | {' | '.join(cells)} | " in printed  # the scorecard's row
    assert (tmp_path / "out" / "results.md").read_text().splitlines()[2].startswith("| vae | ")
    assert (tmp_path / "out" / "disentanglement.png").exists()
    # More samples than the data holds, or none: refused before any model is loaded or evaluated.
    code, _, err = cli(*args[:5], tmp_path / "out2", *args[6:], "--n", 121)
    assert code == 2 and "n = 121 is more than the 120 real trajectories" in err and not (tmp_path / "out2").exists()
    code, _, err = cli(*args, "--n", 0)
    assert code == 2 and "argument --n: must be an integer >= 1, got 0" in err
    # An evaluation already at --out is replaced only with --overwrite.
    results = (tmp_path / "out" / "results.json").read_bytes()
    code, _, err = cli(*args, "--n", 50)
    assert code == 2 and "already holds an evaluation (results.json); pass --overwrite" in err
    assert (tmp_path / "out" / "results.json").read_bytes() == results
    assert cli(*args, "--n", 50, "--overwrite")[0] == 0 and (tmp_path / "out" / "results.json").read_bytes() != results


def test_evaluate_generators_checks_its_arguments_first(tmp_path) -> None:
    generator = two_factor_generator()
    real = generator.decode(generator.sample_prior(50, 0))
    calls = []
    generator.decode = lambda alpha: calls.append(alpha) or real  # any evaluation would decode
    for kwargs, message in (
        ({"n": 51}, "n = 51 is more than the 50 real trajectories"),
        ({"n": 0}, "n must be an integer >= 1, got 0"),
        ({"dwpr_n": 10**12}, "dwpr_n = 1000000000000 needs about"),
        ({"k": 2.5}, r"k must be an integer >= 1, got 2.5 \(float\)"),
        ({"seed": -1}, "seed must be an integer between 0 and"),
        ({"device": "bogus"}, "device must be 'auto' or a torch device"),
        ({"k": 40}, "k must be smaller than n .*, got k=40 with n=40"),
    ):
        with pytest.raises(ValueError, match=message):
            evaluate_generators([generator], real, **{"n": 40, "dwpr_n": 10, "out_dir": tmp_path / "out", **kwargs})
    (tmp_path / "file").write_text("")
    with pytest.raises(ValueError, match="is a file; expected a folder"):
        evaluate_generators([generator], real, n=40, dwpr_n=10, out_dir=tmp_path / "file")
    with pytest.raises(ValueError, match="model 'missing' .* does not exist"):
        evaluate_generators([tmp_path / "missing.pt"], real, n=40, dwpr_n=10, out_dir=tmp_path / "out")
    (tmp_path / "damaged.pt").write_bytes(b"not a generator")  # read only once the arguments pass: still before out
    with pytest.raises(ValueError, match="is not a sb3-genrl generator file"):
        evaluate_generators([generator, tmp_path / "damaged.pt"], real, n=40, dwpr_n=10, out_dir=tmp_path / "out")
    assert calls == [] and not (tmp_path / "out").exists()


def test_an_empty_dataset_is_refused_naming_it(tmp_path, cli, hockey_generator) -> None:
    generator = two_factor_generator()
    empty = tmp_path / "empty.npy"
    np.save(empty, np.zeros((0, generator.horizon, generator.action_dim), np.float32))
    with pytest.raises(ValueError, match=r"^'.*empty.npy' holds no trajectories \(shape \(0, ") as error:
        evaluate_generators([generator], empty, n=40, dwpr_n=10, out_dir=tmp_path / "out")
    assert str(empty) in str(error.value) and "pass n" not in str(error.value)
    with pytest.raises(ValueError, match="the trajectories array holds no trajectories"):
        evaluate_generators([generator], np.zeros((0, 4, 2)), n=40, dwpr_n=10, out_dir=tmp_path / "out")
    np.save(empty, np.zeros((0, 69, 7), np.float32))  # the command, with a generator file of its shape
    code, _, err = cli("evaluate", hockey_generator, "--data", empty, "--out", tmp_path / "out", "--device", "cpu")
    assert code == 2 and err.startswith(f"genrl evaluate: error: '{empty}' holds no trajectories") and err.count("\n") == 1
    assert not (tmp_path / "out").exists()


def test_evaluate_generator_is_the_one_evaluation_and_independent_of_list_order(tmp_path) -> None:
    from sb3_genrl.metrics import evaluate_generator, real_subset

    generators = {"A": two_factor_generator(ignored_dims=0), "B": two_factor_generator(ignored_dims=1)}
    real_all = generators["A"].decode(generators["A"].sample_prior(300, 5))
    real = real_subset(real_all, 120, seed=4)
    # The subset: 120 distinct rows of the data in their original order, fixed by the seed alone.
    picked = [int(np.flatnonzero((real_all == row).all(axis=(1, 2)))[0]) for row in real]
    assert len(set(picked)) == 120 and picked == sorted(picked)
    np.testing.assert_array_equal(real_subset(real_all, 120, seed=4), real)
    assert real_subset(real_all, 500, seed=4) is real_all

    alone = evaluate_generator(generators["B"], real, n=90, k=3, dwpr_n=30, interventions=3, seed=4, name="B", device="cpu")
    listed = evaluate_generators(
        {"A": generators["A"], "B": generators["B"]},
        real_all,
        n=120,
        k=3,
        dwpr_n=30,
        interventions=3,
        seed=4,
        out_dir=tmp_path,
        device="cpu",
    )
    # The list's real set is the same subset; each model's draws depend on the seed, not on its place in the list.
    again = evaluate_generator(generators["B"], real, n=120, k=3, dwpr_n=30, interventions=3, seed=4, device="cpu")
    assert listed[1].row() | {"model": "x"} == again.row() | {"model": "x"}
    # Independent check of precision and recall: the prior samples of the seed's first stream, brute force.
    prior_rng = np.random.default_rng(np.random.SeedSequence(4).spawn(2)[0])
    generated = generators["B"].decode(generators["B"].sample_prior(90, prior_rng))
    precision, recall, _, _ = brute_force(real, generated, 3)
    assert (alone.precision_recall.precision, alone.precision_recall.recall) == (precision, recall)
    from test_density_coverage import brute_force as density_coverage_brute_force

    density, coverage = density_coverage_brute_force(real, generated, 3)
    assert (alone.density_coverage.density, alone.density_coverage.coverage) == (density, coverage)
    assert alone.name == "B" and alone.details()["num_generated"] == 90


def test_interrupted_outputs_leave_no_partial_file(tmp_path, monkeypatch) -> None:
    from matplotlib.figure import Figure

    from sb3_genrl.metrics.plots import labelled_scatter

    def killed_savefig(self, path, **kwargs):
        with open(path, "wb") as file:
            file.write(b"\x89PNG half")  # what a kill during the write leaves behind
        raise KeyboardInterrupt

    monkeypatch.setattr(Figure, "savefig", killed_savefig)
    with pytest.raises(KeyboardInterrupt):
        labelled_scatter([0.1, 0.2], [0.3, 0.4], ["a", "b"], tmp_path / "plot.png", xlabel="x", ylabel="y")
    table = correlation_table([{"model": f"m{i}", "precision": i, "recall": 1 - i, "score": i} for i in range(4)])
    monkeypatch.setattr("csv.writer", lambda *args, **kwargs: (_ for _ in ()).throw(KeyboardInterrupt()))
    with pytest.raises(KeyboardInterrupt):
        table.to_csv(tmp_path / "table.csv")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("scale", [1e20, 3e35, 1e-20, 1e-30])
@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_precision_recall_equals_brute_force_for_very_large_and_very_small_values(scale: float, dtype: type) -> None:
    rng = np.random.default_rng(0)
    real = (rng.normal(size=(60, 5)) * scale).astype(dtype)
    generated = (rng.normal(0.3, 1.1, size=(50, 5)) * scale).astype(dtype)
    expected = brute_force(real, generated, 3)
    assert 0.3 < expected[0] < 1 and 0.3 < expected[1] < 1
    for batch_size in (7, None):
        result = precision_recall(real, generated, 3, batch_size=batch_size, device="cpu", return_radii=True)
        assert (result.precision, result.recall) == expected[:2], (batch_size, result)
        np.testing.assert_allclose(result.real_radii, expected[2], rtol=1e-12, atol=0)
        np.testing.assert_allclose(result.generated_radii, expected[3], rtol=1e-12, atol=0)


def test_precision_recall_matches_brute_force_on_blocks_ranked_by_groups_of_columns() -> None:
    # Blocks wide enough for the grouped ranking of rows and columns, square and not (the last block of each set is
    # narrower), on grids full of duplicates and exactly tied distances.
    rng = np.random.default_rng(3)
    real, generated = grid_points(rng, 700, 3), grid_points(rng, 650, 3)
    for k in (1, 3):
        expected = brute_force(real, generated, k)
        for batch_size in (None, 256, 211):
            result = precision_recall(real, generated, k, batch_size=batch_size, device="cpu", return_radii=True)
            assert (result.precision, result.recall) == expected[:2], (k, batch_size, result)
            np.testing.assert_allclose(result.real_radii, expected[2], rtol=1e-12, atol=0)
            np.testing.assert_allclose(result.generated_radii, expected[3], rtol=1e-12, atol=0)


def test_radii_with_tied_next_neighbours_are_settled_without_a_second_pass(monkeypatch) -> None:
    # On a square grid an inner point's 4 nearest neighbours all lie at distance 1 and the next at sqrt(2): with
    # k = 3 its k-th and (k+1)-th neighbours tie, which the kept candidates settle without recomputing its row.
    grid = np.stack(np.meshgrid(np.arange(12.0), np.arange(12.0)), axis=-1).reshape(-1, 2)
    generated = grid + np.random.default_rng(0).normal(0, 0.3, size=grid.shape)
    recomputed = []
    original = precision_recall_module._exact_sq_radii_rows

    def counting(points, factors, rows, *args):
        recomputed.append(len(rows))
        return original(points, factors, rows, *args)

    monkeypatch.setattr(precision_recall_module, "_exact_sq_radii_rows", counting)
    for batch_size in (None, 50):
        result = precision_recall(grid, generated, 3, batch_size=batch_size, device="cpu", return_radii=True)
        expected = brute_force(grid, generated, 3)
        assert (result.precision, result.recall) == expected[:2]
        np.testing.assert_allclose(result.real_radii, expected[2], rtol=1e-12, atol=0)
    assert recomputed == []


def test_precision_recall_refuses_values_whose_squared_distances_overflow_float64() -> None:
    points = np.random.default_rng(0).normal(size=(20, 4))
    with pytest.raises(ValueError, match="overflow") as error:
        precision_recall(points * 1e160, points)
    assert "generated" in str(error.value) or "real" in str(error.value)


def test_prior_rollout_equals_a_loop_over_goals_and_draws_stepped_one_by_one() -> None:
    from conftest import FastReachEnv, LinearGenerator

    from sb3_genrl.metrics.prior_rollout import prior_rollout

    generator, goals = LinearGenerator(), np.array([[0.5, -0.2], [-0.6, 0.3], [0.0, 0.7]])
    result = prior_rollout(generator, FastReachEnv(), contexts=goals, draws=4, seed=9)
    alphas = generator.sample_prior(12, np.random.default_rng(np.random.SeedSequence(9).spawn(1)[0]))
    env, expected = FastReachEnv(), []
    for g, goal in enumerate(goals):
        rewards = []
        for alpha in np.clip(alphas[4 * g : 4 * g + 4], -3, 3):  # GenRL's action box
            env.reset(options={"goal": goal})
            for action in generator.decode(alpha[None])[0]:
                _, reward, terminated, _, _ = env.step(action)
            assert terminated
            rewards.append(reward)
        expected.append(max(rewards))
    np.testing.assert_allclose(result.best, expected, rtol=1e-6)
    summary = result.summary()
    assert summary["prior_median"] == pytest.approx(np.median(expected)) and summary["prior_episodes"] == 12
    assert summary["prior_q25"] <= summary["prior_median"] <= summary["prior_q75"]


def test_prior_rollout_on_hockey_plays_the_held_out_goals_of_its_seed_one_trajectory_at_a_time(hockey_generator) -> None:
    from sb3_genrl.baselines.feedback import held_out_goals

    from sb3_genrl.generative import load
    from sb3_genrl.metrics.prior_rollout import PRIOR_ROLLOUT_SEED, prior_rollout

    generator = load(hockey_generator, device="cpu")
    result = prior_rollout(generator, "hockey", contexts=2, draws=2)
    alphas = generator.sample_prior(4, np.random.default_rng(np.random.SeedSequence(PRIOR_ROLLOUT_SEED).spawn(1)[0]))
    # decoded in one batch, as the rollout decodes them (torch's float32 results depend on the batch, and the
    # simulation is chaotic enough to show it), then each played alone for its goal
    trajectories = generator.decode(np.clip(alphas, -3, 3))
    env, expected = gym.make("GenRL/Hockey-v0").unwrapped, []
    for g, goal in enumerate(held_out_goals("hockey", 2, PRIOR_ROLLOUT_SEED)):
        expected.append(max(env.play_trajectory(trajectories[i], goal)[0] for i in (2 * g, 2 * g + 1)))
    np.testing.assert_allclose(result.best, expected, atol=1e-6)
    assert result.solved is None and "prior_success" not in result.summary()  # hockey reports no success
    with pytest.raises(ValueError, match="contexts must be a count or goals of shape"):
        prior_rollout(generator, "hockey", contexts=np.zeros(2), draws=1)


def test_scorecard_ranks_converged_models_by_recall_or_a_measure_given_and_sets_apart_the_untrained() -> None:
    from sb3_genrl.metrics.scorecard import NOT_CONVERGED_PRECISION, rank_key, ranked, scorecard_markdown

    def row(name, precision, recall, prior):
        return {
            "model": name,
            "precision": precision,
            "recall": recall,
            "density": 1.0,
            "coverage": 0.5,
            "delta_1": 0.5,
            "mean_delta": 0.4,
            "prior_median": prior,
            "prior_q25": prior - 0.1,
            "prior_q75": prior + 0.1,
            "prior_episodes": 8,
            "prior_seconds": 0.5,
        }

    rows = [
        row("A", 0.9, 0.2, -0.3),
        row("B", NOT_CONVERGED_PRECISION - 0.01, 0.9, -0.01),
        row("C", 0.5, 0.4, -0.1),
        row("D", NOT_CONVERGED_PRECISION, 0.6, -0.2),
    ]
    assert rank_key(rows) == "recall" and [r["model"] for r in ranked(rows)] == ["D", "C", "A", "B"]
    lines = scorecard_markdown(rows).splitlines()
    assert lines[0].startswith("Ranked by recall (higher is better)") and lines[-1].startswith("| 4 | B |")
    assert lines[-1].endswith("| not converged |") and lines[-2].endswith("| ok |")
    assert [r["model"] for r in ranked(rows, "prior_median")] == ["C", "D", "A", "B"]
    assert scorecard_markdown(rows, "prior_median").startswith("Ranked by the prior rollout")
    without_prior = [{key: value for key, value in r.items() if not key.startswith("prior")} for r in rows]
    assert [r["model"] for r in ranked(without_prior)] == ["D", "C", "A", "B"]
    assert "prior median" not in scorecard_markdown(without_prior)
    # a sparse 0/-1 reward: equal medians, ranked by the mean (the share solved), its success column shown
    sparse = [
        row("E", 0.9, 0.5, -1.0) | {"prior_mean": -0.9, "prior_success": 0.1},
        row("F", 0.9, 0.5, -1.0) | {"prior_mean": -0.6, "prior_success": 0.4},
    ]
    assert [r["model"] for r in ranked(sparse, "prior_median")] == ["F", "E"]
    assert "| prior success |" in scorecard_markdown(sparse) and "prior success" not in scorecard_markdown(rows)
    # ranked by another measure: the order follows it, the rule line names it, unconverged models still come last
    rows[0]["mean_delta"], rows[2]["mean_delta"], rows[1]["mean_delta"] = 0.1, 0.3, 0.9
    assert [r["model"] for r in ranked(rows, "mean_delta")] == ["D", "C", "A", "B"]
    assert scorecard_markdown(rows, "mean_delta").startswith("Ranked by mean_delta (higher is better)")
    with pytest.raises(ValueError, match="cannot rank by 'fid'"):
        ranked(rows, "fid")
    with pytest.raises(ValueError, match="cannot rank by 'prior_median': A, B, C, D lack it"):
        ranked(without_prior, "prior_median")
    # another threshold: at 0 every model is ranked by the measure alone; above D's precision, D joins B at the end
    assert [r["model"] for r in ranked(rows, min_precision=0)] == ["B", "D", "C", "A"]
    assert "no precision threshold" in scorecard_markdown(rows, min_precision=0)
    assert "not converged" not in scorecard_markdown(rows, min_precision=0).split("\n", 1)[1]
    assert [r["model"] for r in ranked(rows, min_precision=0.4)] == ["C", "A", "B", "D"]
    assert "precision below 0.4 is not converged" in scorecard_markdown(rows, min_precision=0.4)
    for bad in (-0.1, 1.5, float("nan")):
        with pytest.raises(ValueError, match="min_precision must be a number in"):
            ranked(rows, min_precision=bad)


def test_genrl_evaluate_with_a_task_prints_the_ranked_scorecard_with_the_prior_rollout(
    tmp_path, cli, hockey_generator
) -> None:
    import json
    import shutil

    from sb3_genrl.generative import load
    from sb3_genrl.metrics.prior_rollout import prior_rollout

    generator = load(hockey_generator, device="cpu")
    np.save(tmp_path / "real.npy", generator.decode(generator.sample_prior(60, np.random.default_rng(0))))
    shutil.copy(hockey_generator, tmp_path / "second.pt")
    code, out, err = cli(
        "evaluate",
        hockey_generator,
        tmp_path / "second.pt",
        "--data",
        tmp_path / "real.npy",
        "--n",
        40,
        "--dwpr-n",
        8,
        "--interventions",
        2,
        "--task",
        "hockey",
        "--contexts",
        3,
        "--draws",
        2,
        "--prior-seed",
        11,
        "--out",
        tmp_path / "eval",
        "--device",
        "cpu",
    )
    assert code == 0, err
    expected = prior_rollout(generator, "hockey", contexts=3, draws=2, seed=11).summary()
    results = json.loads((tmp_path / "eval" / "results.json").read_text())
    for result in results:
        assert result["prior_median"] == pytest.approx(expected["prior_median"], abs=1e-9)
        assert result["prior_episodes"] == 6 and len(result["prior_best"]) == 3
    assert "Ranked by recall" in out and f"| {expected['prior_median']:.3f} |" in out
    assert (tmp_path / "eval" / "scorecard.md").read_text().strip() in out
    # A task without the fast path (a Fetch task): the prior rollout through the step path, with its success.
    from sb3_genrl.generative import make_generator

    fetch = make_generator("VAE-FETCH", horizon=50, action_dim=4, device="cpu")
    fetch.save(str(tmp_path / "fetch.pt"))
    np.save(tmp_path / "fetch_real.npy", fetch.decode(fetch.sample_prior(60, np.random.default_rng(0))))
    code, out, err = cli(
        "evaluate",
        tmp_path / "fetch.pt",
        "--data",
        tmp_path / "fetch_real.npy",
        "--n",
        40,
        "--dwpr-n",
        8,
        "--interventions",
        2,
        "--task",
        "fetch-reach",
        "--contexts",
        3,
        "--draws",
        2,
        "--prior-seed",
        11,
        "--out",
        tmp_path / "fetch",
        "--device",
        "cpu",
    )
    assert code == 0, err
    assert "fetch-reach has no fast path (play_trajectories): the prior rollout plays its 3 x 2 episodes" in out
    rollout = prior_rollout(fetch, "fetch-reach", contexts=3, draws=2, seed=11)
    result = json.loads((tmp_path / "fetch" / "results.json").read_text())[0]
    assert result["prior_best"] == rollout.best.tolist() and result["prior_episodes"] == 6
    assert result["prior_success"] == rollout.summary()["prior_success"] == np.mean(rollout.best == 0.0)
    assert "Ranked by recall" in out and "prior success" in out


def test_prior_rollout_uses_all_cores_by_default_and_its_result_does_not_depend_on_them(hockey_generator) -> None:
    from sb3_genrl.generative import load
    from sb3_genrl.metrics.prior_rollout import prior_rollout

    generator = load(hockey_generator, device="cpu")
    results = [prior_rollout(generator, "hockey", contexts=4, draws=3, seed=2, n_threads=n) for n in (1, 2, None)]
    for result in results[1:]:
        np.testing.assert_array_equal(result.best, results[0].best)


def test_an_evaluation_inside_its_dataset_is_refused(tmp_path) -> None:
    generator = two_factor_generator()
    dataset = tmp_path / "demos"
    dataset.mkdir()
    np.save(dataset / "real.npy", generator.decode(generator.sample_prior(50, 0)))
    for out in (dataset, dataset / "evaluation"):
        with pytest.raises(ValueError, match="would join the dataset's own; choose another path"):
            evaluate_generators([generator], dataset, n=40, dwpr_n=10, out_dir=out)
    assert sorted(path.name for path in dataset.iterdir()) == ["real.npy"]
