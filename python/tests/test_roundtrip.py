import numpy as np
import pytest

import ltm
from conftest import relative_l2, smooth_matrix


@pytest.mark.parametrize("mode", ["adaptive", "2d", "4d", "pca"])
def test_compress_open_export_meets_the_target(matrix, mode):
    data = ltm.compress(matrix, mode=mode, max_error=0.02)
    assert isinstance(data, bytes)
    f = ltm.open(data)
    t = f.export()
    assert t.dtype == np.float32 and t.shape == matrix.shape
    assert t.flags["C_CONTIGUOUS"]
    error = relative_l2(t, matrix)
    assert error <= 0.02
    # The file states the error its decoder measured: the same matrix.
    assert error == pytest.approx(f.error, rel=1e-3)


def test_compress_to_a_path_and_from_a_raw_store(matrix, tmp_path):
    out = tmp_path / "a.ltm"
    stats = ltm.compress(matrix, out, max_error=0.01, bits=12)
    assert stats["file_bytes"] == out.stat().st_size
    assert stats["bits"] == 12 and stats["target_met"]
    assert stats["achieved_error"] == pytest.approx(ltm.open(out).error, rel=1e-6)
    assert ltm.compress(matrix, max_error=0.01, bits=12) == out.read_bytes()


def test_both_quantizers_meet_the_target(matrix):
    uniform = ltm.compress(matrix, max_error=0.02)
    peak = ltm.compress(matrix, max_error=0.02, quantizer="peak")
    assert uniform != peak
    for data in (uniform, peak):
        f = ltm.open(data)
        assert f.error <= 0.02


def test_float64_and_strided_input_match_float32(matrix):
    a = ltm.compress(matrix, max_error=0.05)
    assert ltm.compress(matrix.astype(np.float64), max_error=0.05) == a
    strided = np.asfortranarray(matrix)
    assert ltm.compress(strided, max_error=0.05) == a


def test_grey_matrix_with_albedo_and_rectangular_image():
    t = smooth_matrix(width=16, height=8, n=2, channels=1)
    albedo = np.linspace(0.1, 0.9, 16 * 8 * 3, dtype=np.float32).reshape(8, 16, 3)
    f = ltm.open(ltm.compress(t, width=16, height=8, albedo=albedo, max_error=0.01))
    assert f.meta["has_albedo"] and f.dims["width"] == 16 and f.dims["height"] == 8
    assert relative_l2(f.export(), t) <= 0.01
    # Relit: the grey image times the albedo.
    light = np.ones((24, 3), np.float32)
    image, _ = f.relighter().relight(light, terms="all")
    exact = (f.export() @ light[:, 0]).reshape(8, 16, 1) * albedo
    assert relative_l2(image, exact) < 1e-5


def test_progress_reports_stages(matrix):
    seen = []
    ltm.compress(matrix, max_error=0.05, progress=lambda s, d, t: seen.append((s, d, t)))
    stages = [s for s, _, _ in seen]
    assert stages[0] == "import" and "coding" in stages
    assert all(d <= t for _, d, t in seen)
