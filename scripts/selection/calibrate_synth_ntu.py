"""Calibrate the synthetic NTU stand-in: how hard is held-out-subject classification?

Baseline: per sample, keep the main bodies (pyskl rules: spread denoising, at least
12 frames, most motion first), centre every frame on body 0's SpineBase, and pool
each joint coordinate over the frames where the body is seen (mean, std, min, max;
both bodies, zero when absent: 600 features). Train on subjects {1, 2, 4, 5, 8, 9},
test on {3, 6, 7, 10}; report accuracy for logistic regression and an RBF SVM.

Usage::

    python scripts/selection/calibrate_synth_ntu.py                    # default config
    python scripts/selection/calibrate_synth_ntu.py --set difficulty=0.5 --set jitter_m=0.02
    python scripts/selection/calibrate_synth_ntu.py --sweep             # the knob table
    python scripts/selection/calibrate_synth_ntu.py --files /tmp/ntu   # write + read real files

The same baseline on a prepared cache, beside the learned models:
``mocapkit compare ntu_recognition benchmark.root=CACHE``. Samples are generated in memory with ``synthesize_sample`` (identical to the files up
to their 7 printed digits) unless ``--files`` is given.
"""

from __future__ import annotations

import argparse
import ast
import tempfile
import time

import numpy as np
from sklearn.linear_model import LogisticRegression
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler
from sklearn.svm import SVC

from mocapkit.datasets.formats.ntu_skeleton import read_skeleton, select_main_bodies
from mocapkit.datasets.synthetic.ntu import NTUSynthConfig, perform, sample_names, synthesize_ntu, synthesize_sample
from mocapkit.features.pooled import PooledJointStatistics

TRAIN_SUBJECTS = (1, 2, 4, 5, 8, 9)
TEST_SUBJECTS = (3, 6, 7, 10)


def main_bodies(seq) -> np.ndarray:
    """The two main bodies ``[2, T, 25, 3]`` (pyskl rules), zeros where a body is not seen."""
    return select_main_bodies(seq, max_bodies=2, denoise_spread=True, min_frames=12).positions


def dataset(config: NTUSynthConfig, files: str | None = None):
    """Features ``[N, 600]``, labels ``[N]`` and subjects ``[N]`` for every sample of ``config``."""
    names = sample_names(config)
    if files:
        paths = synthesize_ntu(files, config, workers=2, progress=False)
        seqs = (read_skeleton(p) for p in paths)
    else:
        cache = {}

        def gen():
            for n in names:
                key = (n.setup, n.subject, n.replication, n.action)
                if key not in cache:
                    cache.clear()
                    cache[key] = perform(config, *key)
                yield synthesize_sample(n, config, cache[key])

        seqs = gen()
    X = PooledJointStatistics(bodies=2).fit_transform([main_bodies(s) for s in seqs])
    y = np.array([n.action - 1 for n in names])
    subj = np.array([n.subject for n in names])
    return X, y, subj


def evaluate(config: NTUSynthConfig, files: str | None = None) -> dict[str, float]:
    """Held-out-subject accuracy of the two baselines (needs ``num_subjects >= 10``)."""
    X, y, subj = dataset(config, files)
    train, test = np.isin(subj, TRAIN_SUBJECTS), np.isin(subj, TEST_SUBJECTS)
    out = {}
    models = {
        "logreg": make_pipeline(StandardScaler(), LogisticRegression(C=0.1, max_iter=3000)),
        "rbf_svm": make_pipeline(StandardScaler(), SVC(C=10.0, gamma="scale")),
    }
    for name, model in models.items():
        model.fit(X[train], y[train])
        out[name] = float((model.predict(X[test]) == y[test]).mean())
        out[name + "_train"] = float((model.predict(X[train]) == y[train]).mean())
    return out


SWEEP = [
    {},
    {"difficulty": 0.0},
    {"difficulty": 0.5},
    {"difficulty": 1.5},
    {"difficulty": 2.0},
    {"style_noise": 5.0},
    {"style_noise": 15.0},
    {"sample_noise": 3.0},
    {"sample_noise": 10.0},
    {"jitter_m": 0.0, "drop_frame_prob": 0.0, "extra_body_prob": 0.0},
    {"jitter_m": 0.03},
    {"extra_body_prob": 0.5},
    {"num_classes": 20},
]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="FIELD=VALUE",
        help="override an NTUSynthConfig field (Python literal), repeatable",
    )
    parser.add_argument("--sweep", action="store_true", help="run the knob table instead")
    parser.add_argument("--files", metavar="DIR", help="write real files to DIR ('tmp' for a temp dir) and read them")
    args = parser.parse_args()
    base = {}
    for item in args.set:
        key, _, value = item.partition("=")
        base[key] = ast.literal_eval(value)
    rows = [dict(base, **s) for s in SWEEP] if args.sweep else [base]
    chance = None
    for overrides in rows:
        config = NTUSynthConfig(**overrides)
        chance = 1.0 / config.num_classes
        t0 = time.perf_counter()
        if args.files == "tmp":
            with tempfile.TemporaryDirectory() as tmp:
                acc = evaluate(config, tmp)
        else:
            acc = evaluate(config, args.files)
        print(
            f"{str(overrides or 'default'):70s} logreg {acc['logreg']:.3f} (train {acc['logreg_train']:.3f})  "
            f"rbf-svm {acc['rbf_svm']:.3f} (train {acc['rbf_svm_train']:.3f})  chance {chance:.3f}  "
            f"[{time.perf_counter() - t0:.1f}s]",
            flush=True,
        )


if __name__ == "__main__":
    main()
