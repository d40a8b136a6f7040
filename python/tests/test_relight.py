import subprocess
import threading

import numpy as np
import pytest

import ltm
from conftest import ENVMAP, ltm_binary, relative_l2


def test_relight_matches_numpy(ltm_path, matrix, sky):
    f = ltm.open(ltm_path)
    r = f.relighter()
    light = r.cubemap(sky)
    assert light.shape == (96, 3) and light.dtype == np.float32
    image, stats = r.relight(sky, terms="all")
    assert image.shape == (16, 16, 3) and image.dtype == np.float32
    assert 0 < stats["lights"] <= 96 and stats["frame_ms"] >= 0
    # The decoded matrix times the light, to float rounding...
    decoded = np.einsum("pjc,jc->pc", f.export().astype(np.float64), light)
    assert relative_l2(image.reshape(-1, 3), decoded) < 1e-5
    # ...and the exact T·L within the file's stated error.
    exact = np.einsum("pjc,jc->pc", matrix.astype(np.float64), light)
    assert relative_l2(image.reshape(-1, 3), exact) <= f.error


def test_light_forms_agree(ltm_path, sky, tmp_path):
    r = ltm.open(ltm_path).relighter()
    by_map, _ = r.relight(sky, terms=50)
    by_cube, _ = r.relight(r.cubemap(sky), terms=50)
    by_faces, _ = r.relight(r.cubemap(sky).reshape(6, 4, 4, 3), terms=50)
    # Any memory order reads as its values (a Fortran-ordered cubemap too).
    by_fortran, _ = r.relight(np.asfortranarray(r.cubemap(sky)), terms=50)
    by_map_fortran, _ = r.relight(np.asfortranarray(sky), terms=50)
    ltm.write_exr(tmp_path / "sky.exr", sky)
    by_file, _ = r.relight(tmp_path / "sky.exr", terms=50)
    for other in (by_cube, by_faces, by_fortran, by_map_fortran, by_file):
        assert np.array_equal(by_map, other)
    rotated, _ = r.relight(sky, terms=50, rotation=(90, 0, 0))
    assert np.array_equal(rotated, r.relight(r.cubemap(sky, (90, 0, 0)), terms=50)[0])
    assert not np.array_equal(rotated, by_map)


@pytest.mark.parametrize("terms,weighting", [(20, "unweighted"), (50, "transport"), ("all", "area")])
def test_relight_is_the_cli_bit_for_bit(ltm_path, tmp_path, terms, weighting):
    ltm_bin = ltm_binary()
    out = tmp_path / "cli.exr"
    subprocess.run(
        [ltm_bin, "relight", str(ltm_path), "--env", str(ENVMAP), "--terms", str(terms),
         "--weighting", weighting, "--rotate", "30,10,0", "-o", str(out)],
        check=True, capture_output=True,
    )
    cli = ltm.read_exr(out)
    r = ltm.open(ltm_path).relighter()
    for _ in range(2):  # a second frame in the same (pooled) frame too
        image, _ = r.relight(ENVMAP, terms=terms, weighting=weighting, rotation=(30, 10, 0))
        assert np.array_equal(image, cli)


def test_pca_file_relights_and_is_the_cli(matrix, tmp_path, sky):
    path = tmp_path / "p.ltm"
    ltm.compress(matrix, path, mode="pca", max_error=0.01)
    r = ltm.open(path).relighter()
    assert r.term_basis == "linear"
    image, stats = r.relight(sky)
    assert stats["lights"] == r.max_terms
    exact = np.einsum("pjc,jc->pc", matrix.astype(np.float64), r.cubemap(sky))
    assert relative_l2(image.reshape(-1, 3), exact) <= 0.01
    with pytest.raises(ValueError):
        r.relight(sky, terms=r.max_terms + 1)


def test_threads_relight_at_once(ltm_path, sky):
    r = ltm.open(ltm_path).relighter()
    lights = [r.cubemap(sky, (15.0 * k, 0, 0)) for k in range(8)]
    expected = [r.relight(l, terms=40)[0] for l in lights]
    results = {}

    def work(k):
        for _ in range(5):
            image, _ = r.relight(lights[k], terms=40)
            if not np.array_equal(image, expected[k]):
                results[k] = False
                return
        results[k] = True

    threads = [threading.Thread(target=work, args=(k,)) for k in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert results == {k: True for k in range(8)}


def test_reference_is_the_exact_product(matrix, tmp_path, sky):
    raw = tmp_path / "m.raw"
    # A raw store from the matrix, via the CLI's own import when there is one.
    np.save(tmp_path / "m.npy", matrix)
    ltm_bin = ltm_binary()
    subprocess.run([ltm_bin, "import", str(tmp_path / "m.npy"), "--width", "16",
                    "--height", "16", "-o", str(raw)], check=True, capture_output=True)
    image = ltm.reference(raw, sky)
    r = ltm.open(ltm.compress(raw, max_error=0.01)).relighter()
    exact = np.einsum("pjc,jc->pc", matrix.astype(np.float64), r.cubemap(sky))
    assert relative_l2(image.reshape(-1, 3), exact) < 1e-6
