"""A missing ../shared skips a test on a laptop and fails it in CI."""

import conftest
import pytest
from _pytest.outcomes import Failed, Skipped


@pytest.mark.parametrize("value, fails", [("", False), ("0", False), ("false", False), ("true", True), ("1", True)])
def test_missing_shared_data_skips_or_fails_by_ci(monkeypatch, value, fails):
    monkeypatch.setenv("CI", value)
    with pytest.raises(Failed if fails else Skipped, match="nowhere"):
        conftest.missing("nowhere to be found")


def test_the_mesh_fixture_honours_its_override(monkeypatch, tmp_path):
    monkeypatch.setenv("VISUOTACTILE_SHARED_MESHES", str(tmp_path / "absent"))
    monkeypatch.setenv("CI", "true")
    with pytest.raises(Failed, match="not found"):
        conftest.shared_meshes.__wrapped__()
