"""HDM05 clip names, the 130/65/25 class tables and their merge rules, cross-actor splits."""

import numpy as np
import pytest

from mocapkit.datasets.hdm05.splits import k_actors_train, leave_one_actor_out
from mocapkit.datasets.mocap import hdm05_classes as hdm05
from mocapkit.datasets.mocap.hdm05_classes import (
    ACTORS,
    HDM05ClipName,
    class_index_map,
    class_names,
    class_table,
    labels,
    merge_25,
    merge_65,
    parse_clip_name,
)


def test_clip_names():
    c = parse_clip_name("punchLFront1Reps_bd_003.amc")
    assert c == HDM05ClipName("punchLFront1Reps", "bd", 3, None) and str(c) == "punchLFront1Reps_bd_003"
    c = parse_clip_name("/data/HDM05_cut_amc/cartwheelLHandStart1Reps/HDM_bd_cartwheelLHandStart1Reps_004_120.amc")
    assert (c.cls, c.actor, c.take, c.fps) == ("cartwheelLHandStart1Reps", "bd", 4, 120)
    assert c.class65 == "cartwheel" and c.class25 == "cartwheel"
    with pytest.raises(ValueError, match="not an HDM05 clip name"):
        parse_clip_name("HDM_dg_06-03_03_120.amc")  # a whole take, not a cut clip
    with pytest.raises(ValueError, match="unknown HDM05 actor"):
        parse_clip_name("punchLFront1Reps_xx_001")
    with pytest.raises(ValueError, match="not one of the 130"):
        parse_clip_name("punchLFront9Reps_bd_001")
    assert parse_clip_name("punchLFront9Reps_xx_001", strict=False).actor == "xx"


def test_class_table_sizes_and_known_names():
    rows = class_table()
    assert len(rows) == 130 and len({r[0] for r in rows}) == 130
    assert len(class_names(130)) == 130 and len(class_names(65)) == 65 and len(class_names(25)) == 25
    assert class_names(130)[0] == "cartwheelLHandStart1Reps" and class_names(130)[-1] == "walkRightCrossFront3Steps"
    for name in ("walkRightCrossFront3Steps", "hitRHandHead", "staircaseUp3Rstart", "jogOnPlaceStartFloor4StepsRStart"):
        assert name in class_names(130)
    with pytest.raises(ValueError):
        class_names(64)


def test_data_file_follows_the_documented_rules():
    for c130, c65, c25 in class_table():
        assert merge_65(c130) == c65, c130
        assert merge_25(c130) == c25 == merge_25(c65), c130
    # every 65-class maps into exactly one 25-class
    pairs = {(c65, c25) for _, c65, c25 in class_table()}
    assert len(pairs) == 65


def test_65_merge_matches_the_literature_examples():
    assert merge_65("punchLFront1Reps") == merge_65("punchLFront2Reps") != merge_65("punchRFront1Reps")
    assert merge_65("walk2StepsLstart") == merge_65("walk4StepsRstart") == "walk"
    assert merge_65("cartwheelLHandStart1Reps") == merge_65("cartwheelRHandStart1Reps")
    assert merge_65("elbowToKnee1RepsLelbowStart") == merge_65("elbowToKnee3RepsRelbowStart")
    assert merge_65("jogOnPlaceStartAir2StepsLStart") == merge_65("jogOnPlaceStartFloor4StepsRStart")
    assert merge_65("throwSittingHighR") == merge_65("throwSittingLowR") != merge_65("throwStandingLowR")
    assert merge_65("hopLLeg1hops") != merge_65("hopRLeg1hops")
    assert merge_65("staircaseUp3Rstart") == "staircaseUp" != merge_65("staircaseDown3Rstart")
    assert merge_65("grabHighR") != merge_65("grabLowR")
    assert merge_65("walkLeft2Steps") == merge_65("walkLeft3Steps") != merge_65("walkLeftCircle4StepsLstart")


def test_25_merge_is_the_stem():
    assert set(class_names(25)) == {
        "cartwheel",
        "clap",
        "deposit",
        "elbowToKnee",
        "grab",
        "hitRHandHead",
        "hop",
        "jog",
        "jumpDown",
        "jumpingJack",
        "kick",
        "lieDownFloor",
        "punch",
        "rotateArms",
        "runOnPlace",
        "shuffle",
        "sitDown",
        "skier",
        "sneak",
        "squat",
        "staircase",
        "standUp",
        "throw",
        "turn",
        "walk",
    }
    assert merge_25("punchRSide2Reps") == "punch" and merge_25("walkRightCircle6StepsLstart") == "walk"
    assert merge_25("jumpDown") != merge_25("jumpingJack1Reps")  # different leading words
    assert merge_25("turnLeft") == merge_25("turnRight") == "turn"
    with pytest.raises(ValueError):
        merge_25("flyAway")


def test_labels():
    names = [
        "punchLFront1Reps",
        "punchLFront2Reps",
        "punchRFront1Reps_bd_001",
        HDM05ClipName("kickLSide1Reps", "tr", 1),
    ]
    l130, l65, l25 = labels(names, 130), labels(names, 65), labels(names, 25)
    assert l130.dtype == np.int64 and len(set(l130)) == 4
    assert l65[0] == l65[1] != l65[2] and l25[0] == l25[1] == l25[2] != l25[3]
    assert class_names(25)[l25[0]] == "punch"
    assert l130.tolist() == [
        class_index_map(130)[n] for n in ("punchLFront1Reps", "punchLFront2Reps", "punchRFront1Reps", "kickLSide1Reps")
    ]


def test_leave_one_actor_out():
    actors = ["bd", "bk", "dg", "mm", "tr", "bd", "dg"]
    train, test = leave_one_actor_out(actors, "bd")
    assert test.tolist() == [0, 5] and train.tolist() == [1, 2, 3, 4, 6] and train.dtype == np.int64
    folds = leave_one_actor_out(actors)
    assert [f[0] for f in folds] == list(ACTORS)
    assert sorted(np.concatenate([f[2] for f in folds]).tolist()) == list(range(7))
    clips = ["squat1Reps_dg_001", "HDM_mm_squat1Reps_002_120"]
    assert leave_one_actor_out(clips, "mm")[1].tolist() == [1]
    with pytest.raises(ValueError):
        leave_one_actor_out(actors, "zz")


def test_k_actors_train():
    actors = np.array(list(ACTORS) * 3)
    combos = k_actors_train(actors, k=2)
    assert len(combos) == 10
    for train_actors, train, test in combos:
        assert len(train_actors) == 2 and len(train) == 6 and len(test) == 9
        assert set(actors[train]) == set(train_actors) and not set(actors[test]) & set(train_actors)
    assert len(k_actors_train(actors, k=3)) == 10 and len(k_actors_train(actors, k=1)) == 5
    one = k_actors_train(actors, k=2, seed=7)
    assert one[0] == k_actors_train(actors, k=2, seed=7)[0] and one[0] in [c[0] for c in combos]
    assert len({k_actors_train(actors, k=2, seed=s)[0] for s in range(30)}) > 3
    with pytest.raises(ValueError):
        k_actors_train(actors, k=5)


def test_data_file_header_documents_rules():
    text = hdm05.DATA_FILE.read_text()
    assert "class65" in text and "class25" in text and "leading lower-case word" in text
