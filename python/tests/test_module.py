import pathlib
import re

import pytest

import ltm

ROOT = pathlib.Path(__file__).resolve().parents[2]


def test_version_is_the_workspace_version():
    text = (ROOT / "Cargo.toml").read_text()
    workspace = re.search(r'\[workspace\.package\][^\[]*?version = "([^"]+)"', text)
    assert ltm.__version__ == workspace.group(1)
    # The crate inherits the workspace's version (it is a workspace member).
    crate = (ROOT / "python" / "Cargo.toml").read_text()
    assert re.search(r"^version\.workspace = true$", crate, re.M)


def test_open_errors_carry_the_message(tmp_path):
    with pytest.raises(FileNotFoundError, match="missing.ltm"):
        ltm.open(tmp_path / "missing.ltm")
    with pytest.raises(ValueError, match="magic"):
        ltm.open(b"not an ltm file at all, just some bytes" * 4)
    with pytest.raises(ValueError, match="max_memory"):
        ltm.open(tmp_path / "x.ltm", max_memory="lots")


def test_file_properties(ltm_path, matrix):
    f = ltm.open(ltm_path)
    assert f.dims == {
        "width": 16, "height": 16, "rows": 256, "face_res": 4, "lights": 96,
        "channels": 3, "layout": "image",
    }
    assert f.mode == "adaptive"
    assert 0 < f.error <= 0.01
    assert f.size == ltm_path.stat().st_size
    assert f.shape == (256, 96, 3)
    assert f.meta["target_error"] == pytest.approx(0.01)
    assert f.meta["raw_bytes"] == matrix.nbytes
    from_bytes = ltm.open(ltm_path.read_bytes())
    assert from_bytes.meta == f.meta
    assert "adaptive" in repr(f)
