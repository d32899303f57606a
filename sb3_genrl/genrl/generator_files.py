"""Where a GenRL model finds its generator: the file it was built from, else ``<name>.generator.pt`` saved beside the
model's zip (for a generator built in memory)."""

from __future__ import annotations

import io
import json
import os
import pathlib
import warnings
from typing import Any

import torch as th
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv

from sb3_genrl.generative import load
from sb3_genrl.generative.base import TrajectoryGenerator
from sb3_genrl.generative.file_format import FORMAT_MARKER, payload_digest
from sb3_genrl.wrappers import find_latent_wrapper


def generator_file(path: str | pathlib.Path) -> pathlib.Path:
    """``dir/model.zip`` -> ``dir/model.generator.pt``."""
    path = pathlib.Path(path)
    if path.suffix == ".zip":
        path = path.with_suffix("")
    return path.with_name(path.name + ".generator.pt")


def load_generator(path: str, device: th.device | str) -> TrajectoryGenerator:
    """The generator saved at ``path``, onto ``device`` (:func:`sb3_genrl.generative.load`)."""
    return load(path, device=device)


def save_generator_beside(generator: TrajectoryGenerator, model_path: pathlib.Path) -> None:
    """Save ``generator`` as :func:`generator_file` of ``model_path``, unless it cannot be saved (then loading the
    model needs the generator given)."""
    try:
        generator.save(str(generator_file(model_path)))
    except NotImplementedError:
        pass


def check_model_data(path: Any, data: dict[str, Any] | None) -> None:
    """Refuse what is not a GenRL model zip, before SB3 loads it: a file without SB3's ``data`` entry (a generator
    file, a torch checkpoint: SB3 raises a bare ``AssertionError``) or another algorithm's model (a PPO zip loads and
    fails later with a shape error)."""
    if not data:
        kind = " (a generator file: load it with sb3_genrl.generative.load)" if _is_generator_file(path) else ""
        raise ValueError(
            f"{path} is not an SB3 model zip{kind}; a GenRL model is the .zip that GenRL.save and genrl train-policy write"
        )
    if "n_em_iterations" not in data:
        policy = data.get("policy_class")
        name = getattr(policy, "__name__", None) or "another algorithm's"
        raise ValueError(
            f"{path} is not a GenRL model: it holds a {name} policy of another algorithm (no GenRL "
            "settings); load it with that algorithm's load()"
        )


def _is_generator_file(path: Any) -> bool:
    if not isinstance(path, str | os.PathLike):
        return False
    try:
        return th.load(path, map_location="cpu", weights_only=True).get("format") == FORMAT_MARKER
    except Exception:  # noqa: BLE001 (any file that torch cannot read as ours is not a generator file)
        return False


def saved_generator(
    path: str | pathlib.Path | io.BufferedIOBase,
    data: dict[str, Any],
    generator: TrajectoryGenerator | str | None,
    device: th.device | str,
) -> tuple[TrajectoryGenerator | None, str | None]:
    """The generator of a model loaded from ``path`` whose saved ``data`` is given, and its file (an absolute path):
    ``generator`` when given (a file is loaded onto ``device``), else the first of :func:`generator_candidates` that
    exists; ``(None, None)`` when there is none. One that is not the generator the model recorded is refused
    (:func:`check_recorded_generator`); a model saved without a record of its generator (an older version) is warned
    about."""
    check_model_data(path, data)
    if "generator_sha256" not in data:
        warnings.warn(
            f"{path} was saved without its generator's SHA-256 (by an older sb3-genrl): its generator cannot be "
            "checked against the one the policy was trained with; save it again to record it",
            stacklevel=3,
        )
    generator_path = os.path.abspath(generator) if isinstance(generator, str | os.PathLike) else None
    if generator is None:
        generator_path = next((p for p in generator_candidates(path, data) if os.path.isfile(p)), None)
    if generator_path is not None:
        generator = load_generator(generator_path, device)
    check_recorded_generator(generator, data.get("generator_sha256"), generator_path, path)  # type: ignore[arg-type]
    return generator, generator_path  # type: ignore[return-value]


def generator_candidates(path: str | pathlib.Path | io.BufferedIOBase, data: dict[str, Any]) -> list[str]:
    """Where the generator of a model saved at ``path`` (``data``: its saved data) may be, as absolute paths: the file
    it was built from, then :func:`generator_file` of ``path``."""
    candidates = [data.get("generator_path")] + ([generator_file(path)] if isinstance(path, str | os.PathLike) else [])
    return [os.path.abspath(candidate) for candidate in candidates if candidate is not None]


def warn_without_generator(path: Any, data: dict[str, Any]) -> None:
    """Warn that the model loaded from ``path`` has no generator: none was given and none of
    :func:`generator_candidates` exists (it still predicts latent actions; ``predict_trajectory`` raises)."""
    tried = generator_candidates(path, data)
    warnings.warn(
        f"no generator found for {path}"
        + (f" (none of {', '.join(map(repr, tried))} exists)" if tried else "")
        + ": the model predicts latent actions, but cannot decode them; pass generator= (the generator it was "
        "trained with) to decode or train",
        stacklevel=3,
    )


def generator_digest(generator: TrajectoryGenerator | None) -> str | None:
    """The SHA-256 (hex) of a generator's content: its class, configuration, weights and normalisation statistics,
    what decoding depends on (not its training history or the file it came from, so a generator and its file, or two
    saves of it, agree). ``None`` for a generator that is not a :class:`~sb3_genrl.generative.TorchTrajectoryGenerator`
    (its content is unknown), or none."""
    if generator is None or not (hasattr(generator, "state_tensors") and hasattr(generator, "config")):
        return None

    return payload_digest(
        {
            "format_version": "content",
            "format": "",
            "class": type(generator).__name__,
            "sb3_genrl_version": "",
            "config": json.dumps(generator.config()),
            "history": "",
            "state": generator.state_tensors(),
        }
    )


def describe_generator(generator: TrajectoryGenerator, path: str | os.PathLike | None = None) -> str:
    """``BetaVAE from 'vae.pt' ((latent_dim, T, M) = (2, 69, 7), SHA-256 1a2b3c4d...)``: a generator as the errors
    name it."""
    digest, shape = generator_digest(generator), (generator.latent_dim, generator.horizon, generator.action_dim)
    content = f"SHA-256 {digest[:16]}..." if digest else f"object {id(generator):#x}"
    return (
        f"{type(generator).__name__}"
        + (f" from {os.fspath(path)!r}" if path is not None else "")
        + f" ((latent_dim, T, M) = {shape}, {content})"
    )


def check_recorded_generator(
    generator: TrajectoryGenerator | None, recorded: str | None, path: str | os.PathLike | None, model: Any
) -> None:
    """Refuse a generator whose content is not the one a saved model ``model`` recorded (``recorded``: its
    :func:`generator_digest`) - e.g. a generator file replaced by another ``train-generator`` run since the policy was
    trained on it. A model saved without a record (an older version, a generator of unknown content) is not checked.

    :param path: the file the generator was loaded from (named in the error), if any
    """
    digest = generator_digest(generator)
    if recorded is not None and digest is not None and digest != recorded:
        raise ValueError(
            f"the generator {describe_generator(generator, path)} is not the one {model} was trained with "
            f"(SHA-256 {recorded[:16]}...): a policy decodes its latent actions with its own generator; "
            "pass the generator it was trained with"
        )


def check_same_generator(given: TrajectoryGenerator | None, env: Any, given_path: str | None, model: Any = None) -> None:
    """Refuse a generator given beside an env that already wraps another one (GenRL would train on the env's and save
    the given one). Generators of the same content (:func:`generator_digest`) pass; of unknown content, only the same
    object, or one of the same class when the env's is a copy from an env process.

    :param given: the generator given to the constructor, or a model's own
    :param env: the env given
    :param given_path: the file ``given`` came from (named in the error), if any
    :param model: None: ``given`` was given to the constructor; else the model whose own generator ``given`` is
        (``"this model"``, a zip's path: ``set_env`` and ``load`` with an env), named in the error
    """
    wrapped, copied = wrapped_generator(env)
    if given is None or wrapped is None or given is wrapped:
        return
    digests = generator_digest(given), generator_digest(wrapped)
    if digests[0] is None and digests[1] is None:
        same = copied and type(given) is type(wrapped)
    else:
        same = digests[0] == digests[1]
    if same:
        return
    if model is None:
        raise ValueError(
            f"the generator given, {describe_generator(given, given_path)}, is not the one wrapping the "
            f"env, {describe_generator(wrapped)}: GenRL plays the env's; pass that one, or no generator "
            "(the env's is used)"
        )
    raise ValueError(
        f"the env is wrapped with the generator {describe_generator(wrapped)}, not with {model}'s own, "
        f"{describe_generator(given, given_path)}: the policy would train on the env's and be saved and "
        "evaluated with its own; wrap the env with the model's generator, or pass the env unwrapped (it is "
        "wrapped with the model's)"
    )


def wrapped_generator(env: Any) -> tuple[TrajectoryGenerator | None, bool]:
    """The generator of the :class:`~sb3_genrl.LatentActionWrapper` that ``env`` (or a VecEnv's first env) already is
    or holds (``None`` for a raw env, a Gymnasium id or none), and whether it is a copy (from an env process)."""

    if isinstance(env, VecEnv):
        try:
            return env.get_attr("generator", indices=[0])[0], not isinstance(env.unwrapped, DummyVecEnv)
        except AttributeError:
            return None, False
    wrapper = find_latent_wrapper(env) if hasattr(env, "unwrapped") else None
    return None if wrapper is None else wrapper.generator, False
