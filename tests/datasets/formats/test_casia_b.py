"""CASIA-B silhouette layout: listing (natural sort, stray files, empty and missing folders) and the PNG reader."""

import numpy as np
import pytest
from PIL import Image

from mocapkit.datasets.formats.casia_b import (
    GaitSequence,
    GaitSequenceKey,
    SilhouetteFormatError,
    frame_number,
    list_casia_b,
    read_sequence,
    read_silhouette,
)


def _silhouette(h=24, w=32, value=255, box=(6, 10, 18, 20)):
    image = np.zeros((h, w), dtype=np.uint8)
    y0, x0, y1, x1 = box
    image[y0:y1, x0:x1] = value
    return image


def _write(path, array, mode="L"):
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(array).convert(mode).save(path)
    return path


def _sequence(root, name, frames, h=24, w=32):
    """Write ``frames`` silhouettes into ``root/name`` with CASIA-B names; frame k has a box shifted by k."""
    key = GaitSequenceKey(*_parse(name))
    for k in frames:
        _write(root / name / key.frame_name(k), _silhouette(h, w, box=(4, k % 10, 20, k % 10 + 8)))


def _parse(name):
    subject, walk, view = name.split("/")
    condition, number = walk.split("-")
    return int(subject), condition, int(number), int(view)


# ---------------------------------------------------------------- listing


def test_frame_number_is_the_last_integer_of_the_stem():
    assert frame_number("001-nm-01-090-045.png") == 45
    assert frame_number("img_2.PNG") == 2
    assert frame_number("frame10_mask.png") == 10
    assert frame_number("mask.png") is None


def test_natural_sort_and_odd_names(tmp_path):
    folder = tmp_path / "001" / "nm-01" / "090"
    for name in ("f10.png", "f2.png", "f1.png", "img_033.PNG"):
        _write(folder / name, _silhouette())
    listing = list_casia_b(tmp_path)
    (seq,) = listing.sequences
    assert seq.key == GaitSequenceKey(1, "nm", 1, 90)
    assert [p.name for p in seq.frames] == ["f1.png", "f2.png", "f10.png", "img_033.PNG"]
    assert listing.problems == []


def test_stray_files_and_unnumbered_pngs_are_reported_not_read(tmp_path):
    _sequence(tmp_path, "001/nm-01/000", [1, 2])
    folder = tmp_path / "001" / "nm-01" / "000"
    (folder / "Thumbs.db").write_bytes(b"\x00" * 10)
    (folder / ".DS_Store").write_bytes(b"\x00")
    _write(folder / "preview.png", _silhouette())
    (tmp_path / "001" / "notes.doc").write_text("x")
    (tmp_path / "README.txt").write_text("documentation is not a problem")
    listing = list_casia_b(tmp_path)
    assert len(listing.sequences[0].frames) == 2
    text = "\n".join(listing.problems)
    assert "001/nm-01/000/Thumbs.db: stray file" in text and "001/nm-01/000/.DS_Store: stray file" in text
    assert "preview.png: PNG without a frame number" in text
    assert "001/notes.doc: stray file" in text
    assert "README" not in text and len(listing.problems) == 4


def test_bad_folder_names_are_problems_and_empty_view_folders_listed(tmp_path):
    _sequence(tmp_path, "002/bg-02/180", [1])
    (tmp_path / "002" / "bg-02" / "036").mkdir()  # empty view folder
    (tmp_path / "002" / "xx-01" / "090").mkdir(parents=True)  # unknown condition
    (tmp_path / "002" / "nm-01" / "045").mkdir(parents=True)  # not a CASIA-B view
    (tmp_path / "subjectA").mkdir()
    listing = list_casia_b(tmp_path)
    assert [s.key.name for s in listing.sequences] == ["002/bg-02/036", "002/bg-02/180"]
    assert listing.sequences[0].frames == ()
    text = "\n".join(listing.problems)
    assert "002/bg-02/036: empty view folder" in text
    assert "002/xx-01/090" in text and "002/nm-01/045: view 045" in text and "subjectA: not a subject folder" in text


def test_missing_names_every_absent_subject_condition_view(tmp_path):
    _sequence(tmp_path, "001/nm-01/000", [1])
    _sequence(tmp_path, "001/cl-02/018", [1])
    listing = list_casia_b(tmp_path)
    missing = listing.missing({"nm": 2, "cl": 2})
    # 2 nm + 2 cl walks x 11 views, minus the two present
    assert len(missing) == 4 * 11 - 2
    assert "001/nm-01/000" not in missing and "001/cl-02/018" not in missing
    assert "001/nm-02/090" in missing and "001/cl-01/180" in missing and not any("bg" in m for m in missing)
    # a requested subject with no folder at all is entirely missing
    listing = list_casia_b(tmp_path, subjects=[1, 3])
    assert sum(m.startswith("003/") for m in listing.missing()) == 10 * 11


def test_subject_filter_sorting_and_errors(tmp_path):
    _sequence(tmp_path, "002/nm-01/090", [1])
    _sequence(tmp_path, "001/nm-02/090", [1])
    _sequence(tmp_path, "001/nm-01/180", [1])
    listing = list_casia_b(tmp_path)
    assert [s.key.name for s in listing.sequences] == ["001/nm-01/180", "001/nm-02/090", "002/nm-01/090"]
    assert [s.key.subject for s in list_casia_b(tmp_path, subjects=[2]).sequences] == [2]
    with pytest.raises(ValueError, match="no CASIA-B sequence found for subjects \\[7\\].*<subject>/<condition>-<nn>"):
        list_casia_b(tmp_path, subjects=[7])
    with pytest.raises(FileNotFoundError, match="nowhere"):
        list_casia_b(tmp_path / "nowhere")
    (tmp_path / "empty").mkdir()
    with pytest.raises(ValueError, match="expected <root>/<subject>/<condition>-<nn>/<view>/<frame>.png"):
        list_casia_b(tmp_path / "empty")


# ---------------------------------------------------------------- reading


def test_read_modes_gray_1bit_rgb_rgba_and_16bit(tmp_path):
    mask = _silhouette()
    expected = np.where(mask > 0, 255, 0)
    for mode in ("L", "1", "RGB", "RGBA", "P"):
        out = read_silhouette(_write(tmp_path / f"{mode}-001.png", mask, mode))
        assert out.dtype == np.uint8 and out.shape == mask.shape, mode
        np.testing.assert_array_equal(out, expected, err_msg=mode)
    Image.fromarray(mask.astype(np.uint16) * 257).save(tmp_path / "i16-001.png")
    np.testing.assert_array_equal(read_silhouette(tmp_path / "i16-001.png"), expected)


def test_some_edge_gray_is_thresholded_at_128(tmp_path):
    mask = _silhouette(h=40, w=40, box=(5, 5, 35, 35))
    mask[5, 5:35] = 100  # 30 of 1600 pixels (1.9 %) gray: tolerated, below 128 -> background
    mask[34, 5:35] = 200  # above 128 -> foreground
    out = read_silhouette(_write(tmp_path / "x-007.png", mask))
    assert set(np.unique(out)) == {0, 255}
    assert (out[5, 5:35] == 0).all() and (out[34, 5:35] == 255).all()


def test_gray_image_is_rejected_with_file_and_frame(tmp_path):
    gray = np.tile(np.linspace(0, 255, 32, dtype=np.uint8), (24, 1))  # a gradient, not a silhouette
    path = _write(tmp_path / "001-nm-01-090-012.png", gray)
    with pytest.raises(
        SilhouetteFormatError,
        match=r"001-nm-01-090-012\.png, frame 12: not a binary silhouette: "
        r"\d+\.\d% gray pixels",
    ) as info:
        read_silhouette(path)
    assert info.value.frame == 12 and info.value.path == str(path)


def test_corrupt_png_is_rejected_with_file_and_frame(tmp_path):
    good = _write(tmp_path / "a-003.png", _silhouette())
    bad = tmp_path / "001-nm-01-090-004.png"
    bad.write_bytes(good.read_bytes()[:60])  # truncated
    with pytest.raises(SilhouetteFormatError, match=r"001-nm-01-090-004\.png, frame 4: unreadable image"):
        read_silhouette(bad)
    junk = tmp_path / "001-nm-01-090-005.png"
    junk.write_bytes(b"this is not a png at all")
    with pytest.raises(SilhouetteFormatError, match=r"frame 5: unreadable image"):
        read_silhouette(junk)


def test_read_sequence_keeps_order_and_empty_frames(tmp_path):
    folder = tmp_path / "001" / "nm-01" / "090"
    for k in (10, 2, 1):
        _write(folder / f"001-nm-01-090-{k:03d}.png", _silhouette(box=(4, k, 20, k + 6)))
    _write(folder / "001-nm-01-090-011.png", np.zeros((24, 32), np.uint8))  # all-black frame
    (seq,) = list_casia_b(tmp_path).sequences
    frames = read_sequence(seq)
    assert frames.shape == (4, 24, 32) and frames.dtype == np.uint8
    assert [int(np.flatnonzero(f.any(0))[0]) for f in frames[:3]] == [1, 2, 10]
    assert frames[3].max() == 0


def test_read_sequence_frame_size_mismatch_names_the_frame(tmp_path):
    folder = tmp_path / "001" / "nm-01" / "090"
    _write(folder / "001-nm-01-090-001.png", _silhouette(24, 32))
    _write(folder / "001-nm-01-090-002.png", _silhouette(24, 32))
    _write(folder / "001-nm-01-090-003.png", _silhouette(30, 32))
    (seq,) = list_casia_b(tmp_path).sequences
    with pytest.raises(
        SilhouetteFormatError,
        match=r"001-nm-01-090-003\.png, frame 3: frame size 32x30 \(WxH\) "
        r"differs .*001-nm-01-090-001\.png \(32x24\)",
    ):
        read_sequence(seq)


def test_read_sequence_of_an_empty_folder_names_the_folder(tmp_path):
    seq = GaitSequence(GaitSequenceKey(1, "nm", 1, 0), tmp_path, ())
    with pytest.raises(SilhouetteFormatError, match="empty view folder"):
        read_sequence(seq)
