"""The paper's published numbers (shared/seeds paper, Tables 1-4), mean ± std over its 5 seeds.

These are the paper's, not ours: every table and card that shows one labels it "paper". Metric order:
pick_success, drop_success, rearrange_success, fixed_strict, energy_remaining; None where the paper has no
number (× or blank).
"""

from __future__ import annotations

METRIC_NAMES = ("pick_success", "drop_success", "rearrange_success", "fixed_strict", "energy_remaining")
LOWER_IS_BETTER = frozenset({"energy_remaining"})

_Row = tuple[tuple[float, float] | None, ...]

TABLE1: dict[str, _Row] = {
    "Policy w/ GT poses": ((0.795, 0.030), (0.737, 0.017), (0.476, 0.016), (0.603, 0.012), (0.442, 0.011)),
    "ResNet18 + Img": (None, None, None, None, None),  # the paper's × (fails) for Drop and the full task
    "ResNet18 + ΔPose": ((0.272, 0.013), (0.724, 0.028), (0.0132, 0.007), (0.303, 0.010), (0.749, 0.007)),
    "ResNet18 + Landmark": (None, (0.671, 0.029), (0.0036, 0.002), (0.285, 0.006), (0.770, 0.011)),
    "ResNet50 + ΔPose": ((0.413, 0.017), (0.717, 0.020), (0.124, 0.008), (0.350, 0.026), (0.646, 0.024)),
    "ResNet50 + Landmark": (None, (0.655, 0.021), (0.0200, 0.006), (0.318, 0.009), (0.750, 0.011)),
    "Ours": ((0.707, 0.020), (0.665, 0.007), (0.306, 0.031), (0.530, 0.024), (0.529, 0.024)),
}
TABLE2: dict[str, _Row] = {
    "Policy w/ GT poses": TABLE1["Policy w/ GT poses"],
    "Policy w/o uncertainty": ((0.647, 0.024), (0.649, 0.021), (0.224, 0.022), (0.474, 0.020), (0.587, 0.019)),
    "Ours (Policy + uncertainty)": TABLE1["Ours"],
}
TABLE3: dict[str, _Row] = {
    "ResNet50 + ΔPose": ((0.224, 0.019), (0.725, 0.015), (0.0592, 0.044), (0.302, 0.018), (0.732, 0.017)),
    "W/o fine tuning": ((0.538, 0.020), (0.562, 0.020), (0.0668, 0.015), (0.297, 0.013), (0.700, 0.014)),
    "Fine tuning": ((0.545, 0.018), (0.727, 0.014), (0.211, 0.008), (0.448, 0.013), (0.571, 0.011)),
}
TABLE4: dict[int, _Row] = {
    1: ((0.895, 0.015), (0.889, 0.005), (0.939, 0.010), (0.939, 0.010), (0.153, 0.009)),
    2: ((0.752, 0.013), (0.717, 0.018), (0.592, 0.008), (0.716, 0.007), (0.355, 0.006)),
    3: ((0.621, 0.019), (0.604, 0.020), (0.263, 0.024), (0.491, 0.017), (0.558, 0.018)),
    4: ((0.515, 0.024), (0.444, 0.029), (0.0892, 0.008), (0.325, 0.008), (0.709, 0.006)),
    5: ((0.294, 0.014), (0.330, 0.020), (0.0188, 0.006), (0.206, 0.007), (0.814, 0.006)),
}
