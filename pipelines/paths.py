"""Where the stages read and write (relative to the repository root; dvc.yaml names the same paths)."""

from pathlib import Path

EPISODES = Path("datasets/episodes")
MANIFEST = Path("datasets/manifest.parquet")
LEROBOT = Path("datasets/lerobot")
DATASET_CARD = Path("cards/dataset")
VALIDATION_REPORT = Path("datasets/validation/report.json")
COLLECT_STATS = Path("datasets/collect_stats.json")
