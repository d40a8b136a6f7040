"""Shared fixtures: a small smooth transport matrix, its compressed file,
and the `ltm` binary when one is built."""

import os
import pathlib

import numpy as np
import pytest

import ltm

ROOT = pathlib.Path(__file__).resolve().parents[2]
ENVMAP = ROOT / "assets" / "envmaps" / "interior.exr"


def smooth_matrix(width=16, height=16, n=4, channels=3, seed=1):
    """A (P, M, C) or (P, M) float32 matrix: a few smooth products of pixel
    and light patterns plus a little noise, all >= 0."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:height, 0:width] / max(width, height)
    j = np.arange(6 * n * n) / (6 * n * n)
    t = np.zeros((width * height, 6 * n * n, channels))
    for k in range(4):
        a = np.cos((k + 1) * np.pi * x + k) * np.cos((k + 2) * np.pi * y) + 1.2
        b = np.sin((k + 1) * 3 * np.pi * j + k) + 1.1
        c = rng.uniform(0.5, 1.0, channels)
        t += a.reshape(-1, 1, 1) * b.reshape(1, -1, 1) * c / (k + 1)
    t += rng.uniform(0, 0.01, t.shape)
    t = (t * 1e-2).astype(np.float32)
    return t[..., 0].copy() if channels == 1 else t


def relative_l2(a, b):
    a = np.asarray(a, np.float64)
    b = np.asarray(b, np.float64)
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


def ltm_binary():
    """The `ltm` binary: $LTM_BIN, else target/debug or target/release."""
    if os.environ.get("LTM_BIN"):
        return os.environ["LTM_BIN"]
    for profile in ("debug", "release"):
        path = ROOT / "target" / profile / "ltm"
        if path.is_file():
            return str(path)
    if os.environ.get("CI"):
        pytest.fail("no ltm binary (cargo test builds target/debug/ltm; or set LTM_BIN)")
    pytest.skip("no ltm binary built (cargo build, or set LTM_BIN)")


@pytest.fixture(scope="session")
def matrix():
    return smooth_matrix()


@pytest.fixture(scope="session")
def ltm_path(matrix, tmp_path_factory):
    path = tmp_path_factory.mktemp("files") / "m.ltm"
    stats = ltm.compress(matrix, path, max_error=0.01)
    assert stats["target_met"]
    return path


@pytest.fixture(scope="session")
def sky():
    """A (32, 64, 3) lat-long map, brighter above, with a warm sun."""
    y, x = np.mgrid[0:32, 0:64]
    sky = np.zeros((32, 64, 3), np.float32)
    sky[...] = (1.0 + 3.0 * (y < 16))[..., None] * np.array([0.6, 0.7, 1.0])
    sky[4:7, 40:44] = [50.0, 40.0, 20.0]
    return sky
