"""``mor bench lnet``: inference throughput of the L-Net, alone and as the streaming step beside the environments.

Two measurements: the model's single-frame step at several batch sizes on random frames, and the streaming step
(``LNetRunner.step``, observations converted included) at batch N beside N environments' own rendered steps in
the same loop and process, each timed separately (frames/s each and their ratio). Weights are random: the cost
does not depend on them.
"""

from __future__ import annotations

import os
import platform
import statistics
import time
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from torch.utils.flop_counter import FlopCounterMode

from mor.lnet.calibration import Calibration
from mor.lnet.model import LNet
from mor.lnet.params import LNetConfig
from mor.lnet.runtime import LNetRunner
from mor.sim.config import SimConfig
from mor.sim.rules import N_ACTIONS

STREAMING_ENV = "MOR/Rearrange-v0"


@torch.no_grad()
def benchmark_lnet(config: LNetConfig, image_size: int, batch_sizes: list[int], repeats: int,
                   steps: int = 20) -> dict[str, Any]:
    """Median frames/s over ``repeats`` runs of ``steps`` single-frame steps (state carried) per batch size, and
    the multiply-adds of one frame's step (torch's FLOP counter: convolutions and matrix products), the whole
    model's and its image encoder's."""
    model = LNet(config).eval()
    results = {}
    for batch in batch_sizes:
        images = torch.rand(batch, 1, 3, image_size, image_size)
        classes = torch.tensor([[0, 7, 13, -1, -1]]).expand(batch, -1)
        held = torch.full((batch, 1), -1)
        actions = torch.zeros((batch, 1), dtype=torch.long)
        per_frame = {}
        with FlopCounterMode(display=False) as counter:
            model(images, classes, held, actions)  # also the warm-up
        per_frame["model"] = counter.get_total_flops() / 2 / batch
        with FlopCounterMode(display=False) as counter:
            model.posenet.encoder.encode(images[:, 0])
        per_frame["encoder"] = counter.get_total_flops() / 2 / batch
        rates = []
        for _ in range(repeats):
            state = None
            start = time.perf_counter()
            for _ in range(steps):
                _, _, state = model(images, classes, held, actions, state)
            rates.append(batch * steps / (time.perf_counter() - start))
        results[f"batch_{batch}"] = {"frames_per_s": statistics.median(rates), "runs": rates,
                                     "multiply_adds_per_frame": per_frame}
    return {"benchmark": "lnet", "config": config.model_dump(), "image_size": image_size, "device": "cpu",
            "torch_threads": torch.get_num_threads(), "torch": torch.__version__, "results": results,
            "machine": {"cpus": os.cpu_count(), "platform": platform.platform()}}


def benchmark_streaming(config: LNetConfig, sim: SimConfig, n_envs: int, steps: int, repeats: int,
                        seed: int = 0) -> dict[str, Any]:
    """The environments' rendered steps and the L-Net's streaming step over the same ``n_envs`` envs (random
    actions, resets included): median frames/s of each over ``repeats`` runs of ``steps`` vector steps, and
    ``lnet_over_env`` = L-Net frames/s / environment frames/s (>= 1: the L-Net is not the bottleneck)."""
    envs = [gym.make(STREAMING_ENV, **sim.model_dump()) for _ in range(n_envs)]
    runner = LNetRunner(LNet(config), Calibration(), sim.image_size, "benchmark")
    rng = np.random.default_rng(seed)
    observations = [env.reset(seed=seed + i)[0] for i, env in enumerate(envs)]
    state, previous = runner.initial_state(n_envs), np.full(n_envs, -1)
    env_rates, lnet_rates = [], []
    for run in range(repeats + 1):  # run 0 warms up
        env_seconds = lnet_seconds = 0.0
        for _ in range(steps):
            start = time.perf_counter()
            _, state = runner.step(np.stack([o["image"] for o in observations]),
                                           np.stack([o["object_classes"] for o in observations]),
                                           np.array([o["held"] for o in observations]), previous, state)
            lnet_seconds += time.perf_counter() - start
            actions = rng.integers(0, N_ACTIONS, n_envs)
            done = np.zeros(n_envs, dtype=bool)
            start = time.perf_counter()
            for i, env in enumerate(envs):
                observations[i], _, terminated, truncated, _ = env.step(int(actions[i]))
                if terminated or truncated:
                    observations[i], _ = env.reset()
                    done[i] = True
            env_seconds += time.perf_counter() - start
            state, previous = runner.reset(state, done), np.where(done, -1, actions)
        if run:
            env_rates.append(n_envs * steps / env_seconds)
            lnet_rates.append(n_envs * steps / lnet_seconds)
    for env in envs:
        env.close()
    env_rate, lnet_rate = statistics.median(env_rates), statistics.median(lnet_rates)
    return {"n_envs": n_envs, "env_id": STREAMING_ENV, "steps_per_run": steps, "repeats": repeats,
            "env_frames_per_s": env_rate, "lnet_frames_per_s": lnet_rate, "lnet_over_env": lnet_rate / env_rate,
            "runs_env": env_rates, "runs_lnet": lnet_rates, "torch_threads": torch.get_num_threads(),
            "LP_NUM_THREADS": os.environ.get("LP_NUM_THREADS"), "sim": sim.model_dump()}
