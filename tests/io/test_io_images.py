"""Image read/write: lossless deterministic PNG, JPEG by suffix, typed errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from phonestereo.errors import InputError, ShapeError
from phonestereo.io import read_gray, write_image


def _gradient() -> np.ndarray:
    rng = np.random.default_rng(1)
    y, x = np.mgrid[0:120, 0:160]
    return ((x + 2 * y + rng.integers(0, 20, (120, 160))) % 256).astype(np.uint8)


def test_png_lossless_and_deterministic(tmp_path: Path) -> None:
    img = _gradient()
    a = write_image(tmp_path / "sub" / "a.png", img)
    b = write_image(tmp_path / "b.PNG", img.copy())
    assert a.read_bytes() == b.read_bytes()
    back = read_gray(a)
    assert back.dtype == np.uint8 and back.shape == (120, 160)
    assert np.array_equal(back, img)
    assert not list(tmp_path.rglob("*.tmp"))


def test_a_noisy_png_is_lossless_and_smaller(tmp_path: Path) -> None:
    # A sensor-noise image (σ 3 DN about mid-grey): Huffman-only coding keeps every pixel and
    # is smaller than deflate's repeat search, which noise defeats (2000 × 1500 render: 12 %).
    img = np.clip(128 + np.random.default_rng(2).normal(0, 3, (300, 400)), 0, 255).astype(np.uint8)
    fast = write_image(tmp_path / "fast.png", img, noisy=True)
    plain = write_image(tmp_path / "plain.png", img)
    assert np.array_equal(read_gray(fast), img)
    assert fast.stat().st_size < plain.stat().st_size


def test_colour_is_read_as_gray(tmp_path: Path) -> None:
    bgr = np.zeros((10, 12, 3), np.uint8)
    bgr[..., 1] = 200  # pure green → gray 0.587·200 ≈ 117
    g = read_gray(write_image(tmp_path / "c.png", bgr))
    assert g.shape == (10, 12) and abs(int(g[0, 0]) - 117) <= 1


def test_jpeg_by_suffix(tmp_path: Path) -> None:
    img = _gradient()
    p = write_image(tmp_path / "a.jpg", img, jpeg_quality=98)
    assert p.read_bytes()[:2] == b"\xff\xd8"
    # Lossy: mean absolute error of a quality-98 JPEG on this texture is a few grey levels.
    assert np.mean(np.abs(read_gray(p).astype(int) - img)) < 4.0


def test_errors(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="image file not found"):
        read_gray(tmp_path / "none.png")
    (tmp_path / "empty.png").write_bytes(b"")
    with pytest.raises(InputError, match="empty"):
        read_gray(tmp_path / "empty.png")
    (tmp_path / "text.png").write_text("not an image")
    with pytest.raises(InputError, match="cannot decode"):
        read_gray(tmp_path / "text.png")
    with pytest.raises(InputError, match="suffix"):
        write_image(tmp_path / "a.bmp", _gradient())
    with pytest.raises(InputError, match="convert to uint8"):
        write_image(tmp_path / "a.png", _gradient().astype(np.float32))
    with pytest.raises(ShapeError):
        write_image(tmp_path / "a.png", np.zeros((4, 4, 2), np.uint8))
    with pytest.raises(ShapeError):
        write_image(tmp_path / "a.png", np.zeros((0, 4), np.uint8))
