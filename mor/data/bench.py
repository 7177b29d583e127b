"""``mor bench collect``: end-to-end collection throughput (render, PNG encode, MCAP write) and bytes per frame."""

from __future__ import annotations

import os
import platform
import shutil
import statistics
import tempfile
from pathlib import Path
from typing import Any

from mor.data.collect import CollectionSpec, collect


def benchmark_collect(spec: CollectionSpec, episodes: int, worker_counts: list[int], repeats: int,
                      paper_episodes: int = 10_000) -> dict[str, Any]:
    """Median frames/s (wall clock, worker start-up included) for each worker count, bytes per frame on disk,
    and the projected wall time of a ``paper_episodes`` collection at the best measured rate."""
    results: dict[str, Any] = {}
    bytes_per_frame = 0.0
    for workers in worker_counts:
        rates = []
        for _ in range(repeats):
            out_dir = Path(tempfile.mkdtemp(prefix="mor-bench-collect-"))
            try:
                result = collect(spec, out_dir, episodes, workers, progress=False)
                rates.append(result["frames_per_s"])
                size = sum(path.stat().st_size for path in out_dir.glob("*.mcap"))
                bytes_per_frame = size / result["frames"]
            finally:
                shutil.rmtree(out_dir, ignore_errors=True)
        results[f"{workers}_workers"] = {"frames_per_s": statistics.median(rates), "runs": rates}
    best = max(entry["frames_per_s"] for entry in results.values())
    paper_frames = paper_episodes * (spec.episode_steps + 1)
    return {
        "benchmark": "collect",
        "episodes_per_run": episodes,
        "frames_per_episode": spec.episode_steps + 1,
        "repeats": repeats,
        "params": spec.params(),
        "results": results,
        "bytes_per_frame": bytes_per_frame,
        "paper_profile_projection": {
            "episodes": paper_episodes, "frames": paper_frames, "at_frames_per_s": best,
            "hours": paper_frames / best / 3600.0, "disk_gb": paper_frames * bytes_per_frame / 1e9,
        },
        "machine": {"cpus": os.cpu_count(), "platform": platform.platform(), "python": platform.python_version()},
    }
