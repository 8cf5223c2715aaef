import numpy as np

from mocapkit.motion.container import Motion
from mocapkit.train.registry import build_method

# a two-joint motion, 1 s at 120 fps, with a 6-frame gap in the hand and the hand's first 10 frames missing
t = np.linspace(0.0, 1.0, 120)
hand = np.stack([np.sin(2 * np.pi * t), 1.0 + 0.1 * t, np.zeros_like(t)], axis=-1)
positions = np.stack([np.zeros_like(hand), hand], axis=1)  # [frames, joints, 3] metres
positions[40:46, 1] = np.nan
positions[:10, 1] = np.nan
motion = Motion(positions=positions, joint_names=("root", "hand"), parents=(-1, 0), fps=120.0)

refiner = build_method("refinement", "moving-average", ["half_window=4"])  # --method moving-average --set ...
out = refiner.fit([]).refine(motion)

report = out.metadata["refinement"]
print(report)
assert report["filled"] == 6 + 4  # the gap, and the 4 leading frames within reach of a sample
assert report["unfilled"] == {"hand": 6}  # frames 0-5 have no observed sample within 4 frames
np.testing.assert_array_equal(out.positions[~motion.missing], motion.positions[~motion.missing])  # kept as is
