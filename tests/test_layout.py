"""The tests mirror the package layout: each library folder has its tests folder."""

from __future__ import annotations

from import_graph import ROOT


def test_every_library_folder_has_a_tests_folder():
    folders = [path.parent.relative_to(ROOT / "pipeline") for path in (ROOT / "pipeline").rglob("__init__.py")]
    missing = [
        str(folder)
        for folder in folders
        if str(folder) != "."
        and not (ROOT / "tests" / folder).is_dir()
        and not any((ROOT / "tests" / folder).parent.glob(f"test_*{folder.name}*.py"))
    ]
    assert not missing, f"no tests/ folder mirrors pipeline/{missing}"
