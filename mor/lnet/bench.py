"""``mor bench lnet``: inference throughput of the L-Net in the RL loop (PoseNet + one LSTM step per frame)."""

from __future__ import annotations

import os
import platform
import statistics
import time
from typing import Any

import torch

from mor.lnet.model import LNet
from mor.lnet.params import LNetConfig


@torch.no_grad()
def benchmark_lnet(config: LNetConfig, image_size: int, batch_sizes: list[int], repeats: int,
                   steps: int = 20) -> dict[str, Any]:
    """Median frames/s over ``repeats`` runs of ``steps`` single-frame steps (LSTM state carried) per batch size."""
    model = LNet(config).eval()
    results = {}
    for batch in batch_sizes:
        images = torch.rand(batch, 1, 3, image_size, image_size)
        classes = torch.tensor([[0, 7, 13, -1, -1]]).expand(batch, -1)
        held = torch.full((batch, 1), -1)
        actions = torch.zeros((batch, 1), dtype=torch.long)
        model(images, classes, held, actions)  # warm-up
        rates = []
        for _ in range(repeats):
            state = None
            start = time.perf_counter()
            for _ in range(steps):
                _, _, state = model(images, classes, held, actions, state)
            rates.append(batch * steps / (time.perf_counter() - start))
        results[f"batch_{batch}"] = {"frames_per_s": statistics.median(rates), "runs": rates}
    return {"benchmark": "lnet", "config": config.model_dump(), "image_size": image_size, "device": "cpu",
            "torch_threads": torch.get_num_threads(), "torch": torch.__version__, "results": results,
            "machine": {"cpus": os.cpu_count(), "platform": platform.platform()}}
