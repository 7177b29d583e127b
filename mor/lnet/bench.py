"""``mor bench lnet``: inference throughput of the L-Net, alone and as the streaming step beside the environments.

Two measurements: the model's single-frame step at several batch sizes on random frames, and the streaming step
(``LNetRunner.step``, observations converted included) at batch N beside N environments' own rendered steps in
the same loop and process, each timed separately (frames/s each and their ratio). The cost does not depend on
the weights; how far a bfloat16 encoder moves the estimates does, so the streaming step is given its model (the
command passes the committed one where there is one).
"""

from __future__ import annotations

import copy
import os
import platform
import statistics
import time
from dataclasses import fields
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from torch.utils.flop_counter import FlopCounterMode

from mor.lnet.calibration_file import FittedCalibration
from mor.lnet.model import LNet
from mor.lnet.params import LNetConfig
from mor.lnet.runtime import LNetRunner
from mor.lnet.stated import Estimates
from mor.sim.config import SimConfig
from mor.sim.geometry import wrap_angle
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


def benchmark_streaming(model: LNet, fitted: FittedCalibration, sim: SimConfig, n_envs: int, steps: int,
                        repeats: int, seed: int = 0, compiled: bool = True) -> dict[str, Any]:
    """The environments' rendered steps and ``model``'s streaming step over the same ``n_envs`` envs (random
    actions, resets included): median frames/s of each over ``repeats`` runs of ``steps`` vector steps, and
    ``lnet_over_env`` = L-Net frames/s / environment frames/s (>= 1: the L-Net is not the bottleneck).

    The step runs eagerly (float32, as trained) and, with ``compiled``, also through ``torch.compile`` in float32
    (``compiled``) and with a bfloat16 encoder (``compiled_bfloat16``, ``LNet.use_encoder_precision``): the same
    weights and frames, each timed separately in the same loop. Each of those holds its frames/s, ratio, runs,
    the largest difference of its estimates from the eager step's, over all arrays and per array
    (``difference_by_array``: metres, radians; headings wrapped), and the warm-up run's seconds (the
    compilation). ``fitted``: the calibration the step runs with (its tracking settings set on ``model``)."""
    envs = [gym.make(STREAMING_ENV, **sim.model_dump()) for _ in range(n_envs)]
    model = model.eval()
    runners = {"eager": LNetRunner(model, fitted, sim.image_size, "benchmark")}
    if compiled:
        runners["compiled"] = LNetRunner(model, fitted, sim.image_size, "benchmark", compiled=True)
        reduced = copy.deepcopy(model)
        reduced.use_encoder_precision("bfloat16")
        runners["compiled_bfloat16"] = LNetRunner(reduced, fitted, sim.image_size, "benchmark", compiled=True)
    rng = np.random.default_rng(seed)
    observations = [env.reset(seed=seed + i)[0] for i, env in enumerate(envs)]
    states = {name: runner.initial_state(n_envs) for name, runner in runners.items()}
    previous = np.full(n_envs, -1)
    env_rates, lnet_rates = [], {name: [] for name in runners}
    warm_up_seconds = dict.fromkeys(runners, 0.0)
    differences: dict[str, dict[str, float]] = {name: {} for name in runners if name != "eager"}
    for run in range(repeats + 1):  # run 0 warms up (and compiles)
        env_seconds, lnet_seconds = 0.0, dict.fromkeys(runners, 0.0)
        for _ in range(steps):
            inputs = (np.stack([o["image"] for o in observations]), np.stack([o["object_classes"] for o in observations]),
                      np.array([o["held"] for o in observations]), previous)
            estimates = {}
            for name, runner in runners.items():
                start = time.perf_counter()
                estimates[name], states[name] = runner.step(*inputs, states[name])
                lnet_seconds[name] += time.perf_counter() - start
            for name, largest in differences.items():
                for array, value in _differences(estimates["eager"], estimates[name]).items():
                    largest[array] = max(largest.get(array, 0.0), value)
            actions = rng.integers(0, N_ACTIONS, n_envs)
            done = np.zeros(n_envs, dtype=bool)
            start = time.perf_counter()
            for i, env in enumerate(envs):
                observations[i], _, terminated, truncated, _ = env.step(int(actions[i]))
                if terminated or truncated:
                    observations[i], _ = env.reset()
                    done[i] = True
            env_seconds += time.perf_counter() - start
            states = {name: runners[name].reset(state, done) for name, state in states.items()}
            previous = np.where(done, -1, actions)
        if not run:
            warm_up_seconds = lnet_seconds
        else:
            env_rates.append(n_envs * steps / env_seconds)
            for name in runners:
                lnet_rates[name].append(n_envs * steps / lnet_seconds[name])
    for env in envs:
        env.close()
    env_rate = statistics.median(env_rates)
    rates = {name: statistics.median(values) for name, values in lnet_rates.items()}
    result = {"n_envs": n_envs, "env_id": STREAMING_ENV, "steps_per_run": steps, "repeats": repeats,
              "env_frames_per_s": env_rate, "lnet_frames_per_s": rates["eager"],
              "lnet_over_env": rates["eager"] / env_rate, "runs_env": env_rates, "runs_lnet": lnet_rates["eager"],
              "torch_threads": torch.get_num_threads(), "LP_NUM_THREADS": os.environ.get("LP_NUM_THREADS"),
              "data_association": model.tracking.data_association,
              "sim": sim.model_dump()}
    for name, largest in differences.items():
        result[name] = {"lnet_frames_per_s": rates[name], "lnet_over_env": rates[name] / env_rate,
                        "over_eager": rates[name] / rates["eager"], "runs_lnet": lnet_rates[name],
                        "largest_difference": max(largest.values()), "difference_by_array": largest,
                        "warm_up_seconds": warm_up_seconds[name]}
    return result


def _differences(first: Estimates, second: Estimates) -> dict[str, float]:
    """Per float array of two ``Estimates`` of the same frames, the largest absolute difference (headings on the
    circle)."""
    def difference(name: str) -> np.ndarray:
        delta = getattr(first, name) - getattr(second, name)
        return np.abs(wrap_angle(delta) if name == "heading" else delta)

    return {f.name: float(np.max(difference(f.name))) for f in fields(first)
            if getattr(first, f.name) is not None  # search_density: only where the loop keeps the looks
            and getattr(first, f.name).dtype != np.bool_}  # flags (object_searching) have no size of difference
