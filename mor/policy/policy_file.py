"""Policy files that cannot run code: the weights as plain tensors, the architecture as JSON.

SB3's ``policy.save`` pickles the policy's constructor arguments (spaces, classes, a schedule function), so loading
such a file runs whatever a crafted one contains. A MOR policy file is a ``torch.save`` dict of plain values only,
read back with ``torch.load(weights_only=True)``:

- ``format``: ``FORMAT``;
- ``architecture``: a JSON string (``architecture_of``): the observation and action spaces, ``net_arch``, the
  activation and the features extractor by name from an allow-list (``_ACTIVATIONS``, ``_extractors``), their
  keyword arguments;
- ``state_dict``: the policy's tensors.

A training checkpoint (``mor.policy.train``) stores the same two entries plus the optimizer and RNG states.
Files in SB3's pickled format (policies trained before this format) are converted once by ``convert_sb3_policy``,
which the user runs knowingly (``mor policy convert``); nothing else unpickles.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import torch
from gymnasium import spaces
from sb3_contrib.common.maskable.policies import MaskableActorCriticPolicy

from mor.errors import MorError
from mor.tensor_files import UnsafeFile, load_plain, save_plain

FORMAT = "mor.policy/1"
_ACTIVATIONS: dict[str, type[torch.nn.Module]] = {cls.__name__: cls for cls in (torch.nn.Tanh, torch.nn.ReLU)}


def _extractors() -> dict[str, type]:
    from stable_baselines3.common.torch_layers import CombinedExtractor, FlattenExtractor  # noqa: PLC0415

    from mor.policy.baselines import BaselineExtractor  # noqa: PLC0415 - torch vision layers only here

    return {cls.__name__: cls for cls in (FlattenExtractor, CombinedExtractor, BaselineExtractor)}


def _bound(values: np.ndarray) -> float | list:
    """A Box bound as JSON: one number when every entry is equal, else the nested list."""
    flat = np.unique(values)
    return float(flat[0]) if flat.size == 1 else values.astype(np.float64).tolist()


def space_to_json(space: spaces.Space) -> dict[str, Any]:
    """A Box, Discrete or Dict space as plain JSON values (``space_from_json`` reads it back exactly)."""
    if isinstance(space, spaces.Discrete):
        return {"type": "Discrete", "n": int(space.n), "start": int(space.start)}
    if isinstance(space, spaces.Box):
        return {"type": "Box", "shape": list(space.shape), "dtype": space.dtype.name, "low": _bound(space.low),
                "high": _bound(space.high)}
    if isinstance(space, spaces.Dict):
        return {"type": "Dict", "spaces": {key: space_to_json(value) for key, value in space.spaces.items()}}
    raise TypeError(f"a policy's space must be Box, Discrete or Dict, not {type(space).__name__}")


def space_from_json(data: dict[str, Any]) -> spaces.Space:
    """The space that ``space_to_json`` wrote."""
    kind = data["type"]
    if kind == "Discrete":
        return spaces.Discrete(int(data["n"]), start=int(data["start"]))
    if kind == "Box":
        dtype, shape = np.dtype(data["dtype"]), tuple(int(n) for n in data["shape"])
        return spaces.Box(np.broadcast_to(np.asarray(data["low"], dtype), shape).copy(),
                          np.broadcast_to(np.asarray(data["high"], dtype), shape).copy(), shape, dtype)
    if kind == "Dict":
        return spaces.Dict({key: space_from_json(value) for key, value in data["spaces"].items()})
    raise ValueError(f"unknown space type {kind!r}")


def architecture_of(policy: MaskableActorCriticPolicy) -> dict[str, Any]:
    """What rebuilds ``policy`` (without its weights), as plain JSON values."""
    data = policy._get_constructor_parameters()  # noqa: SLF001 - SB3's own record of the constructor's arguments
    return {"observation_space": space_to_json(data["observation_space"]),
            "action_space": space_to_json(data["action_space"]),
            "net_arch": data["net_arch"], "activation_fn": data["activation_fn"].__name__,
            "ortho_init": bool(data["ortho_init"]), "normalize_images": bool(data["normalize_images"]),
            "features_extractor_class": data["features_extractor_class"].__name__,
            "features_extractor_kwargs": data["features_extractor_kwargs"],
            "share_features_extractor": bool(policy.share_features_extractor),  # not in SB3's record above
            "optimizer_kwargs": data["optimizer_kwargs"]}


def build_policy(architecture: dict[str, Any]) -> MaskableActorCriticPolicy:
    """A freshly initialised policy of ``architecture`` (``architecture_of``); names outside the allow-lists are
    refused (ValueError)."""
    extractors = _extractors()
    activation, extractor = architecture["activation_fn"], architecture["features_extractor_class"]
    if activation not in _ACTIVATIONS or extractor not in extractors:
        raise ValueError(f"activation {activation!r} or features extractor {extractor!r} is not one MOR builds")
    return MaskableActorCriticPolicy(
        space_from_json(architecture["observation_space"]), space_from_json(architecture["action_space"]),
        lambda _: 0.0, net_arch=architecture["net_arch"], activation_fn=_ACTIVATIONS[activation],
        ortho_init=architecture["ortho_init"], normalize_images=architecture["normalize_images"],
        features_extractor_class=extractors[extractor],
        features_extractor_kwargs=architecture["features_extractor_kwargs"],
        share_features_extractor=architecture["share_features_extractor"],
        optimizer_kwargs=architecture["optimizer_kwargs"])


def policy_payload(policy: MaskableActorCriticPolicy) -> dict[str, Any]:
    """``format``, ``architecture`` (JSON text) and ``state_dict``: what a policy file and a checkpoint hold."""
    return {"format": FORMAT, "architecture": json.dumps(architecture_of(policy), sort_keys=True),
            "state_dict": policy.state_dict()}


def save_policy_file(policy: MaskableActorCriticPolicy, path: Path) -> None:
    """``policy`` (its architecture and weights) to ``path``, through a temporary name."""
    save_plain(policy_payload(policy), path)


def read_payload(path: Path, kind: str, keys: set[str]) -> dict[str, Any]:
    """The dict of plain values at ``path`` (``torch.load(weights_only=True)``: nothing in it runs), holding at least
    ``keys``. One-line MorError for a missing, damaged or foreign file; ``UnsafeFile`` for a pickle that would
    need code to load (an SB3 file from before ``FORMAT``, or a crafted one). kind: what the file should be, for the
    messages (e.g. "policy file")."""
    path = Path(path)
    if not path.is_file():
        raise MorError(f"{path}: no {kind}; train it first (mor policy train --variant V)")
    saved = load_plain(path, kind, "if it is an SB3 policy file from before MOR's safe format and you trust where it "
                       f"came from, convert it once: mor policy convert {path}", "train it again or fetch it again")
    if not isinstance(saved, dict) or saved.get("format") != FORMAT or not keys <= saved.keys():
        raise MorError(f"{path}: not a MOR {kind} (format {FORMAT} with {', '.join(sorted(keys))}); train it again")
    return saved


def policy_from_payload(saved: dict[str, Any], path: Path) -> MaskableActorCriticPolicy:
    """The policy ``saved`` (``read_payload``) describes, with its weights, in eval mode; one-line MorError naming
    ``path`` when the architecture or the weights do not fit."""
    try:
        policy = build_policy(json.loads(saved["architecture"]))
        policy.load_state_dict(saved["state_dict"])
    except (KeyError, TypeError, ValueError, RuntimeError) as error:
        reason = " ".join(str(error).split())[:200]
        raise MorError(f"{path}: its architecture or weights do not make a policy ({reason}); train it again") \
            from None
    return policy.eval()


def load_policy_file(path: Path) -> MaskableActorCriticPolicy:
    """The policy saved at ``path`` by ``save_policy_file``, without unpickling anything."""
    return policy_from_payload(read_payload(path, "policy file", {"architecture", "state_dict"}), path)


def is_sb3_pickle(path: Path) -> bool:
    """Whether ``path`` holds a policy in SB3's pickled format (it is refused by ``read_payload`` as unsafe)."""
    try:
        read_payload(path, "policy file", set())
    except UnsafeFile:
        return True
    except MorError:
        return False
    return False


def convert_sb3_policy(path: Path) -> None:
    """Rewrite the SB3-pickled policy at ``path`` in MOR's format, in place; the weights come out bit-identical
    (checked). This UNPICKLES the file: only for files the user trusts (``mor policy convert``)."""
    old = MaskableActorCriticPolicy.load(path, device="cpu")
    new_policy = policy_from_payload(policy_payload(old), path)
    for (key, before), after in zip(old.state_dict().items(), new_policy.state_dict().values(), strict=True):
        if not torch.equal(before, after):
            raise MorError(f"{path}: conversion changed {key}; the file was left as it was")
    save_policy_file(new_policy, path)
