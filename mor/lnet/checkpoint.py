"""L-Net checkpoints: what they store, how they are written, and the check that they fit the run that loads them.

A checkpoint is a ``torch.save`` dict of plain values and tensors (read with ``weights_only=True``: loading a
crafted file runs nothing) holding the ``signature`` (``config``: the ``LNetConfig``, which names the
tracker; ``dataset_version``; ``image_size``), the training ``params`` and ``step``, and the ``model`` weights
(plus the optimizer state in the resumable ``checkpoint.pt``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch

from mor.errors import MorError
from mor.lnet.model import LNet
from mor.lnet.params import LNetConfig
from mor.tensor_files import load_plain, save_plain


class CheckpointMismatch(MorError):
    """A checkpoint made with other parameters, data or image size than the run that loads it."""


def signature(config: LNetConfig, dataset_version: str, image_size: int) -> dict[str, Any]:
    """What a checkpoint must agree on with the run that loads it."""
    return {"config": config.model_dump(), "dataset_version": dataset_version, "image_size": image_size}


def check_compatible(saved: dict[str, Any], path: Path, expected: dict[str, Any]) -> None:
    """Raise CheckpointMismatch (one line naming both sides) unless ``saved`` has the ``expected`` signature
    (only the keys ``expected`` names are compared)."""
    for key, ours in expected.items():
        theirs = saved.get(key)
        if theirs != ours:
            if isinstance(ours, dict) and isinstance(theirs, dict):
                theirs, ours = ({k: v for k, v in theirs.items() if ours.get(k) != v},
                                {k: v for k, v in ours.items() if theirs.get(k) != v})
            raise CheckpointMismatch(f"{path}: checkpoint {key} is {theirs} but this run's is {ours}; retrain "
                                     "(mor train-lnet) or use the checkpoint that matches the data and profile")


def load_checkpoint(path: Path, expected: dict[str, Any], device: torch.device | str) -> dict[str, Any]:
    """The checkpoint at ``path``, checked against the ``expected`` signature. Its config is read through
    ``LNetConfig``, so a checkpoint written before a config field existed has that field's default."""
    if not Path(path).is_file():
        raise MorError(f"{path}: no L-Net checkpoint; run mor train-lnet first")
    saved = load_plain(path, "L-Net checkpoint", "use a checkpoint written by mor train-lnet",
                       "retrain or re-fetch it", device)
    if not isinstance(saved, dict) or not {"config", "model", "dataset_version", "image_size"} <= saved.keys():
        raise MorError(f"{path}: not an L-Net checkpoint (it lacks config, model, dataset_version or image_size)")
    saved["config"] = LNetConfig(**saved["config"]).model_dump()
    check_compatible(saved, path, expected)
    return saved


def model_from_checkpoint(saved: dict[str, Any], device: torch.device | str) -> LNet:
    """A fresh LNet of the checkpoint's config with its weights, in eval mode."""
    model = LNet(LNetConfig(**saved["config"])).to(device)
    model.load_state_dict(saved["model"])
    return model.eval()


def load_model(path: Path, expected: dict[str, Any], device: torch.device | str) -> LNet:
    """The weights at ``path`` in a fresh LNet, after checking the checkpoint's signature."""
    return model_from_checkpoint(load_checkpoint(path, expected, device), device)


def save_checkpoint(path: Path, payload: dict[str, Any]) -> None:
    """``payload`` to ``path`` as plain values, through a temporary name (``mor.tensor_files.save_plain``)."""
    save_plain(payload, path)
