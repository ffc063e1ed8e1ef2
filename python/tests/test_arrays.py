"""Arrays in and out: shapes, dtypes, channel orders, strides, and every kind of bad array."""

from __future__ import annotations

import numpy as np
import pytest

import unshear


def grey_of(rgb: np.ndarray) -> np.ndarray:
    weights = np.array([0.299, 0.587, 0.114])
    return np.clip(rgb @ weights + 0.5, 0, 255).astype(np.uint8)


def layouts(rgb: np.ndarray) -> dict[str, np.ndarray]:
    """One image in every layout the binding takes, 8- and 16-bit."""
    grey = grey_of(rgb)
    alpha = np.full(rgb.shape[:2], 255, np.uint8)
    out = {
        "grey": grey,
        "grey1": grey[:, :, None],
        "grey+alpha": np.dstack([grey, alpha]),
        "rgb": rgb,
        "rgba": np.dstack([rgb, alpha]),
    }
    for name, a in list(out.items()):
        out[name + "16"] = a.astype(np.uint16) * 257
    return out


@pytest.mark.parametrize("canvas", ["same", "expand", "crop"])
def test_correct_keeps_layout_and_dtype(
    quick: unshear.Unshear, face: np.ndarray, canvas: str
) -> None:
    expected_h = face.shape[0]
    for name, img in layouts(face).items():
        out = quick.correct(img, 0.3, canvas=canvas)
        assert out.dtype == img.dtype, name
        assert out.ndim == img.ndim, name
        assert out.shape[2:] == img.shape[2:], name
        assert out.flags.c_contiguous and out.flags.writeable, name
        if canvas == "same":
            assert out.shape == img.shape, name
        elif canvas == "expand":
            assert out.shape[1] > img.shape[1] and out.shape[0] == expected_h, name
        else:
            assert out.shape[1] < img.shape[1] and out.shape[0] <= expected_h, name


def test_every_layout_gives_the_face(quick: unshear.Unshear, face: np.ndarray) -> None:
    for name, img in layouts(face).items():
        report = quick.estimate(img)
        assert report.k is not None and abs(report.k - 0.3) <= 0.05, (name, report)
        assert (report.width, report.height) == (img.shape[1], img.shape[0])


def test_sixteen_bit_is_corrected_at_full_depth(face: np.ndarray) -> None:
    img16 = face.astype(np.uint16) * 256 + 3  # values no 8-bit image has
    out16 = unshear.distort(img16, -0.3)
    out8 = unshear.distort(face, -0.3)
    assert out16.dtype == np.uint16 and out8.dtype == np.uint8
    # The same interpolation, without the 8-bit result's rounding to whole levels (up to half
    # a level, 128 in 16 bits, a little more at the edges where the fill is blended in): the
    # 16-bit result keeps the fractions.
    difference = out16.astype(int) - (out8.astype(int) * 256 + 3)
    assert np.abs(difference).max() <= 256
    assert (out16 % 256 != 3).mean() > 0.2


def test_bgr_is_rgb_reversed(quick: unshear.Unshear, face: np.ndarray) -> None:
    # A tinted face: the grey picture depends on which channel is red.
    face = (face * np.array([1.0, 0.75, 0.3])).astype(np.uint8)
    bgr = np.ascontiguousarray(face[:, :, ::-1])
    a = quick.estimate(face).to_dict()
    b = quick.estimate(bgr, bgr=True).to_dict()
    assert a == b
    # Treated as RGB, the swapped channels give another grey picture: not the same numbers.
    assert quick.estimate(bgr).to_dict() != a
    fixed_rgb = quick.correct(face, 0.3)
    fixed_bgr = quick.correct(bgr, 0.3, bgr=True)
    assert np.array_equal(fixed_bgr, fixed_rgb[:, :, ::-1])
    # BGRA keeps alpha last.
    bgra = np.dstack([bgr, np.full(bgr.shape[:2], 7, np.uint8)])
    out = quick.correct(bgra, 0.3, bgr=True)
    assert np.array_equal(out[:, :, :3], fixed_bgr)


def test_any_strides_and_read_only(quick: unshear.Unshear, face: np.ndarray) -> None:
    reference = quick.estimate(face).to_dict()
    reference_fixed = quick.correct(face, 0.2)
    canvas = np.zeros((face.shape[0] + 20, face.shape[1] + 30, 3), np.uint8)
    canvas[7 : 7 + face.shape[0], 11 : 11 + face.shape[1]] = face
    read_only = face.copy()
    read_only.setflags(write=False)
    planar = np.ascontiguousarray(np.moveaxis(face, 2, 0))
    variants = {
        "fortran": np.asfortranarray(face),
        "view into a larger array": canvas[7 : 7 + face.shape[0], 11 : 11 + face.shape[1]],
        "read-only": read_only,
        "channels last of planar": np.moveaxis(planar, 0, 2),
        "negative strides": face[::-1, ::-1].copy()[::-1, ::-1],
    }
    for name, img in variants.items():
        assert not (img.flags.c_contiguous and name != "read-only"), name
        assert quick.estimate(img).to_dict() == reference, name
        assert np.array_equal(quick.correct(img, 0.2), reference_fixed), name
    flipped = face[::-1]
    assert flipped.strides[0] < 0
    assert (
        quick.estimate(flipped).to_dict() == quick.estimate(np.ascontiguousarray(flipped)).to_dict()
    )


def test_big_endian_and_broadcast_views(quick: unshear.Unshear, face: np.ndarray) -> None:
    img16 = face.astype(np.uint16) * 257
    swapped = img16.astype(">u2")
    assert np.array_equal(quick.correct(swapped, 0.2), quick.correct(img16, 0.2))
    # A zero-stride view of one row, small enough to take: read like any other array.
    row = np.arange(64, dtype=np.uint8)
    tiled = np.lib.stride_tricks.as_strided(row, shape=(40, 64), strides=(0, 1))
    assert np.array_equal(quick.correct(tiled, 0.0), np.tile(row, (40, 1)))


def test_one_pixel_and_tiny_images(corrector: unshear.Unshear) -> None:
    for shape in [(1, 1), (1, 1, 1), (1, 1, 3), (1, 1, 4), (2, 1, 3), (1, 7), (7, 1)]:
        img = np.full(shape, 128, np.uint8)
        report = corrector.estimate(img)
        assert report.k is None and report.faces == [], shape
        out = corrector.correct(img, 0.3)
        assert out.shape == img.shape and out.dtype == img.dtype, shape
        with pytest.raises(unshear.NoFaceError):
            corrector.correct(img)


@pytest.mark.parametrize(
    ("make", "match"),
    [
        (lambda: np.zeros((20, 20, 3), np.float32), "uint8 or uint16"),
        (lambda: np.zeros((20, 20, 3), np.float64), "uint8 or uint16"),
        (lambda: np.zeros((20, 20), np.int16), "uint8 or uint16"),
        (lambda: np.zeros((20, 20), np.int8), "uint8 or uint16"),
        (lambda: np.zeros((20, 20), bool), "uint8 or uint16"),
        (lambda: np.zeros((20, 20), np.uint32), "uint8 or uint16"),
        (lambda: np.zeros((20, 20), object), "uint8 or uint16"),
        (lambda: np.zeros((0, 10, 3), np.uint8), "empty"),
        (lambda: np.zeros((10, 0), np.uint8), "empty"),
        (lambda: np.zeros((0, 0), np.uint8), "empty"),
        (lambda: np.zeros((20,), np.uint8), "H x W"),
        (lambda: np.zeros((), np.uint8), "H x W"),
        (lambda: np.zeros((2, 20, 20, 3), np.uint8), "H x W"),
        (lambda: np.zeros((20, 20, 5), np.uint8), "channels"),
        (lambda: np.zeros((20, 20, 0), np.uint8), "channels"),
        (
            lambda: np.lib.stride_tricks.as_strided(
                np.zeros(1, np.uint8), shape=(100_000, 100_000), strides=(0, 0)
            ),
            "over the limit",
        ),
        (
            lambda: np.lib.stride_tricks.as_strided(
                np.zeros(1, np.uint8), shape=(1, 2**33, 3), strides=(0, 0, 0)
            ),
            "over the limit",
        ),
    ],
)
def test_bad_arrays_raise_value_error(corrector: unshear.Unshear, make: object, match: str) -> None:
    img = make()  # type: ignore[operator]
    for call in (
        lambda: corrector.estimate(img),
        lambda: corrector.correct(img, 0.1),
        lambda: corrector.estimate_many([img]),
        lambda: unshear.distort(img, 0.1),
    ):
        with pytest.raises(ValueError, match=match):
            call()


def test_non_arrays_raise_type_error(corrector: unshear.Unshear) -> None:
    for value in [[[1, 2], [3, 4]], "image.png", None, 3, b"\x00" * 12]:
        with pytest.raises(TypeError, match="numpy array"):
            corrector.estimate(value)  # type: ignore[arg-type]


def test_max_pixels_is_checked_before_any_work() -> None:
    small = unshear.Unshear(max_pixels=100)
    assert small.max_pixels == 100
    small.estimate(np.zeros((10, 10), np.uint8))
    with pytest.raises(ValueError, match="11x10 = 110 pixels, over the limit of 100"):
        small.estimate(np.zeros((10, 11), np.uint8))


def test_bad_options_raise_value_error(quick: unshear.Unshear, face: np.ndarray) -> None:
    for kwargs, match in [
        ({"k": float("nan")}, "finite"),
        ({"k": float("inf")}, "finite"),
        ({"k": 0.1, "region": "everything"}, "region"),
        ({"k": 0.1, "canvas": "big"}, "canvas"),
        ({"k": 0.1, "interp": "nearest"}, "interp"),
        ({"k": 1e12, "canvas": "expand"}, "canvas"),
    ]:
        with pytest.raises(ValueError, match=match):
            quick.correct(face, **kwargs)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="finite"):
        unshear.distort(face, float("nan"))
    other = quick.estimate(face[:, :300])
    with pytest.raises(ValueError, match="the report is of a 300x243 image"):
        quick.correct(face, report=other)


def test_no_face_raises_no_face_error(quick: unshear.Unshear) -> None:
    blank = np.full((120, 160, 3), 90, np.uint8)
    with pytest.raises(unshear.NoFaceError, match="no face"):
        quick.correct(blank)
    with pytest.raises(unshear.NoFaceError):
        quick.correct(blank, 0.2, region="face")
    assert issubclass(unshear.NoFaceError, ValueError)
    # With a shear given, a face is not needed.
    assert quick.correct(blank, 0.2).shape == blank.shape


def test_face_region_keeps_the_rest(quick: unshear.Unshear, face: np.ndarray) -> None:
    canvas = np.full((400, 700, 3), 30, np.uint8)
    canvas[60 : 60 + face.shape[0], 40 : 40 + face.shape[1]] = face
    report = quick.estimate(canvas)
    assert report.k is not None
    out = quick.correct(canvas, region="face", report=report)
    assert out.shape == canvas.shape
    # Far from the face nothing moves; on the face the rows do.
    assert np.array_equal(out[:, 600:], canvas[:, 600:])
    assert not np.array_equal(out[100:250, 100:350], canvas[100:250, 100:350])
