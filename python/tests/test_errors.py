import resource

import numpy as np
import pytest

import ltm
from conftest import smooth_matrix

DATA = __import__("pathlib").Path(__file__).parent / "data"


@pytest.mark.parametrize(
    "bad,match",
    [
        (np.zeros((256, 96), np.int32), "dtype"),
        (np.zeros((256, 95), np.float32), "95 columns"),
        (np.zeros((256, 96, 2), np.float32), "channels"),
        (np.zeros((256,), np.float32), "shape"),
        (np.zeros((255, 96), np.float32), "width and height"),
        ([[1.0, 2.0]], "numpy array"),
    ],
)
def test_bad_matrices_are_value_errors(bad, match):
    with pytest.raises(ValueError, match=match):
        ltm.compress(bad)


def test_nan_is_a_value_error_naming_the_element():
    t = smooth_matrix(channels=3)
    t[17, 5, 2] = np.nan
    with pytest.raises(ValueError, match=r"\(17, 5, 2\) is NaN"):
        ltm.compress(t)
    t64 = t.astype(np.float64)
    t64[17, 5, 2] = 1e39  # finite, but beyond float32
    with pytest.raises(ValueError, match=r"\(17, 5, 2\) is inf"):
        ltm.compress(t64)


def test_bad_settings_are_value_errors(matrix):
    for kwargs, match in [
        (dict(mode="3d"), "mode"),
        (dict(bits=20), "bits"),
        (dict(quantizer="lloyd"), "quantizer 'lloyd'.*uniform or peak"),
        (dict(keep=10, max_error=0.1), "keep"),
        (dict(rank=4), "rank"),
        (dict(mode="pca", entropy="zstd"), "entropy"),
        (dict(row_filter="cdf97"), "row filter|orthonormal|filter"),
    ]:
        with pytest.raises(ValueError, match=match):
            ltm.compress(matrix, **kwargs)
    albedo = np.ones((256, 3), np.float32)
    with pytest.raises(ValueError, match="albedo"):
        ltm.compress(matrix, albedo=albedo)


def test_bad_lights_are_value_errors(ltm_path, sky):
    r = ltm.open(ltm_path).relighter()
    cube = r.cubemap(sky)
    for light, match in [
        (np.ones((10, 3), np.float32), "96"),
        (np.ones((8, 8, 3), np.float32), "2·height|width"),
        (np.ones((8, 16, 4), np.float32), "shape"),
        (sky.astype(np.int64), "dtype"),
    ]:
        with pytest.raises(ValueError, match=match):
            r.relight(light)
    bad = cube.copy()
    bad[3, 1] = np.inf
    with pytest.raises(ValueError, match="texel 3"):
        r.relight(bad)
    with pytest.raises(ValueError, match="rotation"):
        r.relight(cube, rotation=(10, 0, 0))
    with pytest.raises(ValueError, match="weighting"):
        r.relight(sky, weighting="heavy")
    with pytest.raises(ValueError, match="terms"):
        r.relight(sky, terms=0)
    with pytest.raises(ValueError, match="texture"):
        r.render(sky, camera=(0, 0, 3), target=(0, 0, 0))
    with pytest.raises(FileNotFoundError):
        r.relight("no-such-map.exr")


def test_huge_claimed_size_is_a_memory_error_before_allocating():
    # tests/data/claims-8192.ltm: a few hundred bytes claiming an 8192²
    # image (made by tools/testkit's ltm_claiming_8192).
    path = DATA / "claims-8192.ltm"
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    f = ltm.open(path, max_memory="256M")
    assert f.dims["width"] == 8192 and f.size < 1024
    with pytest.raises(MemoryError, match="memory budget"):
        f.export()
    with pytest.raises(MemoryError, match="memory budget"):
        f.relighter().relight(np.ones((6, 3), np.float32))
    with pytest.raises(MemoryError, match="memory budget"):
        ltm.open(path.read_bytes(), max_memory=1 << 20).relighter().relight(
            np.ones((6, 3), np.float32))
    grown_kib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before
    assert grown_kib < 300 * 1024


def test_array_options_with_a_raw_store_are_value_errors(tmp_path):
    with pytest.raises(ValueError, match="raw store carries its own"):
        ltm.compress(tmp_path / "m.raw", width=16)
