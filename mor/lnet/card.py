"""The L-Net's model card (Markdown with Hugging Face front matter), generated from the run's files."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import yaml

from mor.atomic import atomic_output



def _row(name: str, before: dict, after: dict, path: tuple[str, ...]) -> str:
    def get(d: dict) -> float:
        for key in path:
            d = d[key]
        return float(d)  # type: ignore[arg-type]

    return f"| {name} | {get(before):.3f} | {get(after):.3f} |"


def render_model_card(metrics: dict[str, Any], params: dict[str, Any], calibration: dict[str, Any],
                      train_summary: dict[str, Any], figures: dict[str, str]) -> str:
    """The card's text; every number comes from the dicts passed in (the stage's own outputs)."""
    before, after = metrics["before_calibration"], metrics["after_calibration"]
    front = {"license": "apache-2.0", "library_name": "pytorch", "tags": ["mor", "localization", "uncertainty",
             "robotics", "lstm"], "datasets": [f"mor-dataset-{metrics['dataset_version']}"],
             "pipeline_tag": "robotics"}
    rows = [
        _row("NLL agent position", before, after, ("nll", "agent_position")),
        _row("NLL heading", before, after, ("nll", "heading")),
        _row("NLL objects", before, after, ("nll", "objects")),
    ]
    for group in ("agent_position", "objects_seen", "heading"):
        for k in (1, 2, 3):
            rows.append(_row(f"coverage {group} {k}σ", before, after, ("coverage", group, f"{k}sigma")))
    nominal = before["coverage"]
    errors = [
        f"| agent position (m) | {before['agent_position_error_m']['median']:.3f} | "
        f"{before['agent_position_error_m']['p90']:.3f} |",
        f"| heading (deg) | {before['heading_error_deg']['median']:.2f} | {before['heading_error_deg']['p90']:.2f} |",
        f"| objects seen earlier (m) | {before['object_position_error_m']['seen']['median']:.3f} | "
        f"{before['object_position_error_m']['seen']['p90']:.3f} |",
        f"| all objects (m) | {before['object_position_error_m']['all']['median']:.3f} | "
        f"{before['object_position_error_m']['all']['p90']:.3f} |",
    ]
    lines = [
        "---", yaml.safe_dump(front, sort_keys=False).strip(), "---", "",
        "# MOR L-Net (PoseNet + LSTM)", "",
        "Estimates the robot's global position (bivariate Gaussian), heading (von Mises) and every object's position "
        "(bivariate Gaussians) from first-person RGB frames, the object class ids, the held-object index and "
        f"{'the previous action' if params['model']['use_actions'] else 'no action input'} "
        "(paper section 4.1; trained with the NLL of Eq. 5 plus the squared errors of the means, see "
        "docs/assumptions.md).", "",
        f"- Dataset version: `{metrics['dataset_version']}`; test split: {before['episodes']} episodes, "
        f"{before['frames']} frames.",
        f"- Training: {train_summary['steps']} steps on {train_summary['device']}, best validation loss "
        f"{train_summary['best_validation_loss']:.3f}, early stop: {train_summary['stopped_early']}.",
        f"- Calibration (fitted on validation): agent σ × {calibration['agent_scale']:.3f}, objects σ × "
        f"{calibration['object_scale']:.3f}, κ × {calibration['kappa_scale']:.3f}.", "",
        "## Errors on the test split (means of the LSTM's estimates)", "",
        "| quantity | median | 90th percentile |", "| --- | --- | --- |", *errors, "",
        "## Likelihood and coverage, before and after calibration", "",
        f"Nominal coverage: 2-D {nominal['nominal_2d']['1sigma']:.3f} / {nominal['nominal_2d']['2sigma']:.3f} / "
        f"{nominal['nominal_2d']['3sigma']:.3f}; heading {nominal['nominal_heading']['1sigma']:.3f} / "
        f"{nominal['nominal_heading']['2sigma']:.3f} / {nominal['nominal_heading']['3sigma']:.3f}.", "",
        "| metric | before | after |", "| --- | --- | --- |", *rows, "",
        f"![reliability]({figures['reliability']})", "",
        "## What the estimates look like", "",
        "Ground truth as stars, estimated 2σ ellipses, the heading's 95% sector (grey):", "",
        f"![estimates]({figures['strip']})", "", f"Animated: [{figures['gif']}]({figures['gif']})", "",
        f"![learning curve]({figures['learning_curve']})", "",
        "## Use", "",
        "```python\nfrom mor.lnet.runtime import load_lnet\n\nrunner = load_lnet(Path(\"cards/lnet/model.pt\"))  "
        "# reads calibration.json beside it\nstate = runner.initial_state(n_envs)\nestimates, state = runner.step("
        "images, object_classes, held, previous_actions, state)  # env observations, (N, ...)\n```", "",
        "Frames must have the training data's image size (checked at every step); `load_lnet(path, expected=...)` "
        "refuses a checkpoint of another config, tracker, dataset version or image size.", "",
        "## Intended use and limits", "",
        "- Trained on random-action episodes of the MOR simulator; its uncertainty is honest only for that data "
        "distribution (check the coverage after calibration before trusting it elsewhere, e.g. on real runs).",
        "- Objects never seen in an episode can only be guessed from the arena's prior: their errors are large by "
        "construction (see 'all objects').",
        "- Encoder trained from scratch (no pretrained weights are reachable here).", "",
        "## Parameters", "", "```yaml", yaml.safe_dump(params, sort_keys=False).strip(), "```", "",
    ]
    return "\n".join(lines)


def write_model_card(path: Path, text: str) -> Path:
    with atomic_output(path) as partial:
        partial.write_text(text)
    return path


def read_json(path: Path) -> dict[str, Any]:
    return json.loads(path.read_text())
