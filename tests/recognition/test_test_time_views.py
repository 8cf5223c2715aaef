"""Test-time augmentation of skeleton classifiers: the fixed views, their dataset and the averaging."""

import math

import numpy as np
import pytest
import torch

from mocapkit.datasets.augment import TestTimeViews, rotate_about_vertical
from mocapkit.datasets.datamodule import ViewDataset
from mocapkit.recognition.evaluate import mean_over_views, views_from_config
from mocapkit.train.config import ConfigError


def _skeleton(frames=30):
    torch.manual_seed(0)
    x = torch.randn(2, frames, 20, 3) + torch.tensor([0.0, 0.0, 3.0])
    x[1, frames - 5 :] = 0.0  # the second body leaves
    return x


def test_views_are_start_centre_end_crops_at_every_rotation():
    x = _skeleton(30)
    views = TestTimeViews(crops=[1.0, 0.9], rotate_deg=[0, 10])
    out = views(x)
    assert len(views) == len(out) == (1 + 3) * 2
    assert [v.shape[1] for v in out] == [30, 30, 27, 27, 27, 27, 27, 27]
    torch.testing.assert_close(out[0], x)  # whole clip, no rotation
    for view, start in zip(out[2::2], (0, 1, 3)):  # unrotated crops: start, centre, end
        torch.testing.assert_close(view, x[:, start : start + 27])
    rotated = out[1]
    assert (rotated[1, 25:] == 0).all()  # absent joints stay zeros
    torch.testing.assert_close(rotated[..., 1], x[..., 1])  # heights kept

    def distances(points):
        return torch.cdist(points, points, compute_mode="donot_use_mm_for_euclid_dist")

    torch.testing.assert_close(
        distances(x[0].reshape(-1, 3)), distances(rotated[0].reshape(-1, 3)), atol=1e-5, rtol=0
    )  # rigid
    assert not torch.allclose(rotated, x)


def test_rotation_by_ninety_degrees_maps_x_to_minus_z():
    x = torch.zeros(1, 1, 2, 3)
    x[0, 0, 0] = torch.tensor([1.0, 0.0, 0.0])
    x[0, 0, 1] = torch.tensor([-1.0, 0.0, 0.0])  # centroid at the origin
    out = rotate_about_vertical(x, math.pi / 2)
    torch.testing.assert_close(out[0, 0, 0], torch.tensor([0.0, 0.0, -1.0]), atol=1e-6, rtol=0)


def test_short_clips_are_kept_whole_and_bad_views_are_refused():
    assert [v.shape[1] for v in TestTimeViews(crops=[0.5], min_frames=8)(_skeleton(6))] == [6, 6, 6]
    assert [v.shape[1] for v in TestTimeViews(crops=[0.5], min_frames=8)(_skeleton(12))] == [8, 8, 8]
    with pytest.raises(ValueError, match="crops"):
        TestTimeViews(crops=[1.2])
    with pytest.raises(ValueError, match="rotate_deg"):
        TestTimeViews(rotate_deg=[])


def test_view_dataset_yields_each_sample_views_in_a_row():
    items = [{"skeleton": _skeleton(20) * (i + 1), "label": i, "index": 10 + i, "subject": 1} for i in range(3)]
    views = TestTimeViews(crops=[1.0, 0.8], rotate_deg=[0])
    data = ViewDataset(items, views)
    assert len(data) == 3 * 4
    assert [data[k]["index"] for k in range(len(data))] == [10] * 4 + [11] * 4 + [12] * 4
    torch.testing.assert_close(data[5]["skeleton"], items[1]["skeleton"][:, :16])  # sample 1, crop at the start


def test_mean_over_views_averages_probabilities_per_sample():
    logits = np.log(np.array([[0.9, 0.1], [0.3, 0.7], [0.2, 0.8], [0.4, 0.6]], dtype=np.float32))
    out = {"logits": logits, "labels": np.array([0, 0, 1, 1]), "indices": np.array([5, 5, 7, 7])}
    mean = mean_over_views(out, 2)
    np.testing.assert_allclose(np.exp(mean["logits"]), [[0.6, 0.4], [0.3, 0.7]], atol=1e-6)
    assert mean["labels"].tolist() == [0, 1] and mean["indices"].tolist() == [5, 7]
    with pytest.raises(RuntimeError, match="groups of 2"):
        mean_over_views({**out, "indices": np.array([5, 7, 5, 7])}, 2)
    with pytest.raises(RuntimeError, match="groups of 3"):
        mean_over_views(out, 3)


def test_eval_views_config_errors_name_the_key():
    from omegaconf import OmegaConf

    assert views_from_config(OmegaConf.create({"eval": {"views": None}})) is None
    assert len(views_from_config(OmegaConf.create({"eval": {"views": {"crops": [1.0, 0.9]}}}))) == 4
    with pytest.raises(ConfigError, match=r"eval.views: unknown key\(s\) \['crop'\]"):
        views_from_config(OmegaConf.create({"eval": {"views": {"crop": [0.9]}}}))
    with pytest.raises(ConfigError, match="eval.views.crops"):
        views_from_config(OmegaConf.create({"eval": {"views": {"crops": [0]}}}))
    with pytest.raises(ConfigError, match="expected a mapping"):
        views_from_config(OmegaConf.create({"eval": {"views": [1.0]}}))
