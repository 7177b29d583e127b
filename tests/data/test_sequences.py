"""The L-Net's sequence loader: windows inside one episode, labels aligned with frames."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from torch.utils.data import DataLoader

from mor.data.episode_io import read_episode
from mor.data.sequences import SequenceWindows


def test_windows_stay_inside_episodes_and_match_records(tiny_dataset: tuple, tiny_collection: Path) -> None:
    _, root, rows = tiny_dataset
    train_rows = [r for r in rows if r["split"] == "train"]
    windows = SequenceWindows(root / "train", window=8, stride=4)
    per_episode = sum(len(range(0, r["n_frames"] - 8 + 1, 4)) for r in train_rows)
    assert len(windows) == per_episode
    item = windows[1]
    assert item["images"].shape == (8, 3, 16, 16)
    assert item["agent_pose"].shape == (8, 3) and item["object_positions"].shape == (8, 5, 2)
    assert int(item["start_frame"]) == 4
    episode = read_episode(tiny_collection / train_rows[int(item["episode_index"])]["file"])
    np.testing.assert_allclose(item["agent_pose"].numpy(), episode.agent_poses[4:12], atol=1e-5)
    np.testing.assert_array_equal(item["actions"].numpy(), episode.actions[4:12])
    np.testing.assert_array_equal(item["held"].numpy(), episode.held[4:12])  # read back from observation.state
    n = len(episode.header.object_classes)
    assert item["object_mask"].tolist() == [True] * n + [False] * (5 - n)
    batch = next(iter(DataLoader(windows, batch_size=3)))
    assert batch["images"].shape == (3, 8, 3, 16, 16)


def test_missing_split_is_a_clear_error(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="mor build-dataset"):
        SequenceWindows(tmp_path, window=4)


def test_environment_observations_and_dataset_windows_give_identical_tensors(
    tiny_dataset: tuple, tiny_collection: Path, tiny_spec,
) -> None:
    # Replay a recorded episode in the environment (same seed, same actions) and convert each live observation
    # with the streaming path; the dataset window of the same frames must hold exactly the same tensors.
    import gymnasium as gym  # noqa: PLC0415
    import torch  # noqa: PLC0415

    from mor.data.collect import ENV_ID  # noqa: PLC0415
    from mor.data.observations import env_to_network  # noqa: PLC0415
    from mor.sim import rules  # noqa: PLC0415

    _, root, rows = tiny_dataset
    train_rows = [r for r in rows if r["split"] == "train"]
    window = SequenceWindows(root / "train", window=None)[0]
    episode = read_episode(tiny_collection / train_rows[int(window["episode_index"])]["file"])
    env = gym.make(ENV_ID, horizon=tiny_spec.episode_steps, **tiny_spec.sim.model_dump())
    observation, _ = env.reset(seed=episode.header.seed)
    live, visible = [], []
    for action in episode.actions:
        live.append(env_to_network(observation["image"][None], observation["object_classes"][None],
                                   np.array([observation["held"]])))
        state = env.unwrapped.state
        visible.append([rules.visible(state, i) for i in range(state.n_objects)])
        if action >= 0:  # -1: the last frame
            observation, *_ = env.step(int(action))
    env.close()
    assert torch.equal(torch.cat([x.images for x in live]), window["images"])
    assert all(torch.equal(x.object_classes[0], window["object_classes"]) for x in live)
    assert torch.equal(torch.cat([x.held for x in live]), window["held"])
    n = len(visible[0])  # the recorded visibility is the simulator's rule on the live state
    np.testing.assert_array_equal(window["visible"][:, :n].numpy(), np.array(visible))
    assert np.array(visible).any() and not window["visible"][:, n:].any()
