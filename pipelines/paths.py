"""Where the stages read and write (relative to the repository root; dvc.yaml names the same paths).

Manifest ``file`` entries are relative to ``DATASETS``.
"""

from pathlib import Path

DATASETS = Path("datasets")
EPISODES = DATASETS / "episodes"          # simulated episodes (stage collect)
REAL_EPISODES = DATASETS / "real"         # imported real runs (mor import-real)
MANIFEST = DATASETS / "manifest.parquet"
LEROBOT = DATASETS / "lerobot"
DATASET_CARD = Path("cards/dataset")
VALIDATION_REPORT = DATASETS / "validation" / "report.json"
COLLECT_STATS = DATASETS / "collect_stats.json"
EPISODE_FOLDERS = (EPISODES, REAL_EPISODES)
