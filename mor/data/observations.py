"""The observation conventions, declared once, and the one conversion from the environment's to the network's.

| quantity       | environment (``mor.sim.env``)      | dataset and L-Net input (this module)                       |
| -------------- | ---------------------------------- | ----------------------------------------------------------- |
| image          | (H, W, 3) uint8, RGB               | stored as that uint8 array (PNG, lossless); the network      |
|                |                                    | reads (3, H, W) float32 in [0, 1] = uint8 / 255              |
| object classes | (n,) class ids                     | (MAX_OBJECTS,) int64, absent slots ``ABSENT_CLASS`` = -1     |
| held           | index of the held object, n: none  | index of the held object, ``NOT_HELD`` = -1: none            |
|                |                                    | (the dataset stores it one-hot in ``observation.state``:     |
|                |                                    | ``observation_state`` / ``held_from_state``)                 |

The environment's convention is Gymnasium's (spaces cannot hold -1); the dataset's is the one every recorded
file, the L-Net and its evaluation use. ``env_to_network`` turns environment observations into the network's
input tensors; the dataset windows (``mor.data.sequences``) use the same ``images_to_tensor``, and a test checks
that both paths give identical tensors for the same frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from mor.data.schema import MAX_OBJECTS, NO_ACTION
from mor.sim.rules import N_ACTIONS

NOT_HELD = -1
ABSENT_CLASS = -1


def pad_classes(classes: np.ndarray) -> np.ndarray:
    """Class ids (..., n) with n <= MAX_OBJECTS -> (..., MAX_OBJECTS) int64, absent slots ``ABSENT_CLASS``."""
    classes = np.asarray(classes)
    n = classes.shape[-1]
    if n > MAX_OBJECTS:
        raise ValueError(f"object_classes: {n} objects, at most {MAX_OBJECTS} are supported")
    out = np.full((*classes.shape[:-1], MAX_OBJECTS), ABSENT_CLASS, np.int64)
    out[..., :n] = classes
    return out


def held_from_env(held: np.ndarray | int, n_objects: int) -> np.ndarray:
    """The environment's held index (n when nothing is held) -> the dataset's (``NOT_HELD`` when none), int64."""
    held = np.asarray(held, np.int64)
    return np.where(held == n_objects, NOT_HELD, held)


def observation_state(held: np.ndarray, previous_actions: np.ndarray) -> np.ndarray:
    """The dataset's ``observation.state`` (``mor.data.schema.STATE_NAMES``) of T frames: held (T,) the dataset's
    index (``NOT_HELD``: none), previous_actions (T,) the action taken before each frame (``NO_ACTION``: none) ->
    (T, MAX_OBJECTS + N_ACTIONS) float32, the held slot one-hot then the previous action one-hot (all 0 for none)."""
    held, previous_actions = np.asarray(held, np.int64), np.asarray(previous_actions, np.int64)
    state = np.zeros((len(held), MAX_OBJECTS + N_ACTIONS), np.float32)
    rows = np.arange(len(held))
    state[rows[held != NOT_HELD], held[held != NOT_HELD]] = 1.0
    moved = previous_actions != NO_ACTION
    state[rows[moved], MAX_OBJECTS + previous_actions[moved]] = 1.0
    return state


def held_from_state(state: np.ndarray) -> np.ndarray:
    """The held index (..., ) int64 (``NOT_HELD`` when none) of ``observation.state`` rows (..., MAX_OBJECTS + ...)."""
    slots = np.asarray(state)[..., :MAX_OBJECTS]
    return np.where(slots.any(axis=-1), slots.argmax(axis=-1), NOT_HELD).astype(np.int64)


def images_to_tensor(images: np.ndarray) -> torch.Tensor:
    """RGB frames (..., H, W, 3) uint8 -> the network's (..., 3, H, W) float32 in [0, 1] (value / 255)."""
    if not isinstance(images, np.ndarray) or images.dtype != np.uint8 or images.ndim < 3 or images.shape[-1] != 3:
        kind = f"{images.dtype} {images.shape}" if isinstance(images, np.ndarray) else type(images).__name__
        raise ValueError(f"images: expected uint8 RGB frames (..., H, W, 3), got {kind}")
    return torch.from_numpy(np.ascontiguousarray(images)).movedim(-1, -3).float().div_(255.0)


def tensor_to_images(images: torch.Tensor | np.ndarray) -> np.ndarray:
    """The inverse of ``images_to_tensor``: (..., 3, H, W) floats in [0, 1] -> (..., H, W, 3) uint8."""
    values = np.asarray(images.detach().cpu() if isinstance(images, torch.Tensor) else images, np.float64)
    return np.clip(np.rint(np.moveaxis(values, -3, -1) * 255.0), 0, 255).astype(np.uint8)


@dataclass(frozen=True)
class NetworkInputs:
    """One frame per environment, in the network's convention (N environments, K = MAX_OBJECTS).

    images (N, 3, H, W) float32 in [0, 1]; object_classes (N, K) int64 (-1 absent); held (N,) int64 (-1 none).
    """

    images: torch.Tensor
    object_classes: torch.Tensor
    held: torch.Tensor


def env_to_network(images: np.ndarray, object_classes: np.ndarray, held: np.ndarray) -> NetworkInputs:
    """Environment observations of N environments -> the network's inputs.

    images (N, H, W, 3) uint8; object_classes (N, n) class ids; held (N,) the environment's index (n: none).
    """
    object_classes = np.asarray(object_classes)
    if object_classes.ndim != 2:
        raise ValueError(f"object_classes: expected (N, n) class ids, got shape {object_classes.shape}")
    n = object_classes.shape[1]
    if not isinstance(images, np.ndarray) or images.shape[:1] != object_classes.shape[:1]:
        got = images.shape if isinstance(images, np.ndarray) else type(images).__name__
        raise ValueError(f"images: expected one frame per environment, (N, H, W, 3) with N = "
                         f"{object_classes.shape[0]}, got {got}")
    held = np.asarray(held)
    if held.shape != object_classes.shape[:1] or np.any((held < 0) | (held > n)):
        raise ValueError(f"held: expected (N,) = {object_classes.shape[:1]} indices in [0, {n}] ({n}: nothing "
                         f"held), got {held.tolist()}")
    return NetworkInputs(images_to_tensor(images), torch.from_numpy(pad_classes(object_classes)),
                         torch.from_numpy(held_from_env(held, n)))
