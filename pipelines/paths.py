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
BUILD_STATS = DATASETS / "build_stats.json"
EPISODE_FOLDERS = (EPISODES, REAL_EPISODES)
LNET = DATASETS / "lnet"                  # training run: checkpoint.pt (resume), model.pt (best), log.csv
LNET_CALIBRATION = LNET / "calibration.json"
LNET_CARD = Path("cards/lnet")            # model card, committed weights, metrics and figures
LNET_ABLATION_CARD = Path("cards/lnet_ablation")  # committed results of mor ablate-lnet, shown by the model card
POLICIES = DATASETS / "policy"           # policy training runs: <variant>/<task>/ checkpoints, logs, TensorBoard
POLICY_CARD = Path("cards/policy")        # committed policies: <variant>/<task>/policy.pth + meta.json, card, curves
ENCODER_CARD = Path("cards/baseline_encoder")  # the pixel baselines' pretrained frame encoder, its card and figure
EVAL = DATASETS / "eval"                  # per-episode records: <method>.jsonl
RESULTS_CARD = Path("cards/results")      # rows/<method>.json, results.json, README.md (the tables)
README = Path("README.md")                 # the repository's front page: its headline results block (mor eval results)
SETTINGS = Path("settings")                # setting workspaces: settings/<name>/ (pipelines/settings.py)
MAIN = Path("../..")                      # the main workspace, seen from a setting's workspace
ROBOT = DATASETS / "robot"                # robot controller runs: <loop>/<method>.jsonl, recordings, episodes
ROBOT_CARD = Path("cards/robot")          # the robot card: results.json, README.md, a sim-as-robot video
