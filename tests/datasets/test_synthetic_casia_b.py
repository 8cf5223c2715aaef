"""Synthetic CASIA-B: layout and names, determinism, binary frames, and that subjects, views and conditions show."""

import dataclasses
import json

import numpy as np
import pytest
from PIL import Image

from mocapkit.datasets.formats.casia_b import (
    GaitSequenceKey,
    list_casia_b,
    parse_sequence_folder,
    read_sequence,
)
from mocapkit.datasets.synthetic.casia_b import (
    BAG_STYLES,
    CasiaBSynthConfig,
    SegmentationNoise,
    WalkVariation,
    draw_subject,
    draw_walk,
    render_views,
    render_walk,
    synthesize_casia_b,
)

SMALL = {"num_subjects": 2, "frames": 12, "height": 48, "views": (0, 90), "conditions": {"nm": 1, "bg": 1, "cl": 1}}


def _clean(subject, view, condition, frames=24, height=64, seed=0):
    """A noise-free walk with no per-walk variation."""
    return render_walk(
        subject, view, condition, frames, height, np.random.default_rng(seed), walk=WalkVariation(), noise=None
    )


def _median_width(frames):
    return np.median([np.ptp(np.flatnonzero(f.any(axis=0))) for f in frames if f.any()])


@pytest.fixture(scope="module")
def small_set(tmp_path_factory):
    out = tmp_path_factory.mktemp("synth")
    folders = synthesize_casia_b(out, CasiaBSynthConfig(**SMALL), progress=False)
    return out, folders


def test_layout_and_names_are_casia_b(small_set):
    out, folders = small_set
    config = CasiaBSynthConfig(**SMALL)
    keys = config.sequence_keys()
    assert len(keys) == 2 * 3 * 2
    assert folders == [out / k.name for k in keys]
    for key, folder in zip(keys, folders):
        assert parse_sequence_folder(folder.relative_to(out)) == key
        assert sorted(p.name for p in folder.iterdir()) == [key.frame_name(t) for t in range(1, 13)]
    listing = list_casia_b(out)
    assert [s.key for s in listing.sequences] == keys
    assert listing.problems == []
    assert listing.missing({"nm": 1, "bg": 1, "cl": 1}, views=(0, 90)) == []
    readme = (out / "README.txt").read_text()
    assert "SYNTHETIC" in readme
    assert json.loads(readme.split("config:\n", 1)[1]) == config.to_dict()


def test_frames_are_binary_with_the_configured_size(small_set):
    out, _ = small_set
    for sequence in list_casia_b(out).sequences:
        frames = read_sequence(sequence)
        assert frames.shape == (12, 48, 64)
        assert set(np.unique(frames)) <= {0, 255}
        assert (frames > 0).any(axis=(1, 2)).mean() >= 0.75  # the walker is seen in most frames
    with Image.open(out / "001" / "nm-01" / "090" / "001-nm-01-090-001.png") as image:
        assert image.mode == "L"
        assert set(np.unique(np.asarray(image))) <= {0, 255}


def test_same_seed_gives_identical_bytes_for_any_workers(small_set, tmp_path):
    out, _ = small_set
    again = synthesize_casia_b(tmp_path / "again", CasiaBSynthConfig(**SMALL), progress=False, workers=2)
    other = synthesize_casia_b(tmp_path / "other", CasiaBSynthConfig(**{**SMALL, "seed": 1}), progress=False)
    same, differ = 0, 0
    for folder, other_folder in zip(again, other):
        for path in sorted(folder.iterdir()):
            relative = path.relative_to(tmp_path / "again")
            assert path.read_bytes() == (out / relative).read_bytes(), relative
            differ += path.read_bytes() != (other_folder / path.name).read_bytes()
            same += 1
    assert same == 12 * 12 and differ > same // 2


def test_written_frames_equal_render_walk(small_set):
    """The data set is exactly what the public renderer gives for the same generators."""
    from mocapkit.datasets.synthetic.casia_b import _VIEW, _WALK, _rng

    out, _ = small_set
    config = CasiaBSynthConfig(**SMALL)
    walk = draw_walk(_rng(0, _WALK, 2, 1, 1))  # subject 2, bg (index 1), bg-01
    frames = render_walk(
        draw_subject(0, 2), 90, "bg", 12, 48, _rng(0, _VIEW, 2, 1, 1, 90), walk=walk, noise=config.noise
    )
    (sequence,) = [s for s in list_casia_b(out, subjects=[2]).sequences if s.key == GaitSequenceKey(2, "bg", 1, 90)]
    np.testing.assert_array_equal(frames, read_sequence(sequence))


def test_side_view_is_wider_than_frontal_and_walker_crosses_the_frame():
    for subject in (1, 2):
        params = draw_subject(0, subject)
        front, side, back = (_clean(params, view, "nm") for view in (0, 90, 180))
        assert _median_width(side) > 1.3 * _median_width(front)
        centre = [np.flatnonzero(f.any(axis=0)).mean() for f in side]
        assert centre[-1] - centre[0] > 10  # left to right, pixels at height 64
        heights = [np.ptp(np.flatnonzero(f.any(axis=1))) for f in front]
        assert heights[-1] > heights[0] and [np.ptp(np.flatnonzero(f.any(axis=1))) for f in back][-1] < heights[-1]


def test_coat_and_every_bag_style_change_the_outline():
    params = draw_subject(0, 1)
    for view in (0, 90, 180):
        nm = (_clean(params, view, "nm") > 0).sum()
        assert (_clean(params, view, "cl") > 0).sum() > 1.12 * nm, view
    for style in range(len(BAG_STYLES)):
        bagged = dataclasses.replace(params, bag_style=style)
        nm, bg = _clean(bagged, 90, "nm"), _clean(bagged, 90, "bg")
        assert (bg > 0).sum() > 1.04 * (nm > 0).sum(), BAG_STYLES[style]


def test_subjects_differ_more_than_walks_of_one_subject():
    """Crude gait energy images (height-normalised, centred): each walk's nearest other walk is its subject's."""

    def gei(frames, height=32, width=24):
        out = []
        for f in frames:
            rows, cols = np.flatnonzero(f.any(axis=1)), np.flatnonzero(f.any(axis=0))
            crop = f[rows[0] : rows[-1] + 1, cols[0] : cols[-1] + 1]
            w = min(width, max(1, round(crop.shape[1] * height / crop.shape[0])))
            canvas = np.zeros((height, width), np.float32)
            canvas[:, (width - w) // 2 : (width - w) // 2 + w] = np.asarray(Image.fromarray(crop).resize((w, height)))
            out.append(canvas / 255)
        return np.mean(out, axis=0).ravel()

    subjects, walks = (1, 2, 3, 4), 3
    rng = np.random.default_rng(5)
    geis = np.stack(
        [
            gei(render_walk(draw_subject(0, s), 90, "nm", 50, 64, rng, noise=None))
            for s in subjects
            for _ in range(walks)
        ]
    )
    labels = np.repeat(subjects, walks)
    distance = ((geis[:, None] - geis[None]) ** 2).sum(-1)
    np.fill_diagonal(distance, np.inf)
    same = labels[:, None] == labels[None]
    assert (labels[distance.argmin(axis=1)] == labels).mean() >= 0.75  # chance: 0.25
    assert distance[same & np.isfinite(distance)].mean() < 0.5 * distance[~same].mean()
    assert draw_subject(0, 1) == draw_subject(0, 1) and draw_subject(0, 1) != draw_subject(0, 2)


def test_gait_cycle_shows_in_the_side_view_width():
    """The side-view width peaks once per step: its autocorrelation peaks at half the subject's period."""
    params = draw_subject(0, 3)
    width = np.array([np.ptp(np.flatnonzero(f.any(axis=0))) for f in _clean(params, 90, "nm", frames=90)], float)
    width -= width.mean()
    acf = np.array([(width[:-lag] * width[lag:]).mean() for lag in range(1, 30)])
    step = 1 + int(np.argmax(acf[5:]) + 5)  # skip the smallest lags
    assert abs(step - params.period / 2) <= 1.5


def test_noise_makes_holes_ragged_edges_and_empty_frames():
    params = draw_subject(0, 1)
    clean = _clean(params, 90, "nm", frames=60)
    noisy = render_walk(
        params,
        90,
        "nm",
        60,
        64,
        np.random.default_rng(0),
        walk=WalkVariation(),
        noise=SegmentationNoise(hole_rate=0.01, edge_noise=1.0, empty_frame_prob=0.1),
    )
    differ = (clean != noisy).mean()
    assert 0.002 < differ < 0.05
    assert 1 <= (~noisy.any(axis=(1, 2))).sum() <= 15  # ~10 % of 60 frames empty
    assert not (~clean.any(axis=(1, 2))).any()


def test_render_views_matches_render_walk():
    params = draw_subject(3, 4)
    walk = WalkVariation(speed=1.02, phase=1.0)
    both = render_views(params, [36, 126], "cl", 10, 40, [np.random.default_rng(1), np.random.default_rng(2)], walk)
    np.testing.assert_array_equal(both[1], render_walk(params, 126, "cl", 10, 40, np.random.default_rng(2), walk))


@pytest.mark.parametrize(
    "change, message",
    [
        ({"num_subjects": 0}, "num_subjects"),
        ({"views": (0, 45)}, "views"),
        ({"conditions": {"xx": 1}}, "conditions"),
        ({"height": 8}, "height"),
        ({"hole_rate": 1.5}, "hole_rate"),
        ({"frames": 0}, "frames"),
    ],
)
def test_bad_config_names_the_field(change, message):
    with pytest.raises(ValueError, match=message):
        CasiaBSynthConfig(**{**SMALL, **change})


def test_config_round_trips_through_dict():
    config = CasiaBSynthConfig(**SMALL)
    assert CasiaBSynthConfig.from_dict(json.loads(json.dumps(config.to_dict()))) == config
    with pytest.raises(ValueError, match="unknown"):
        CasiaBSynthConfig.from_dict({"bogus": 1})
