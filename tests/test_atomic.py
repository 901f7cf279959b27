"""`volseg._atomic.remove_tree`: what ``shutil.rmtree(path, ignore_errors=True)``
removes, its files unlinked in threads when there are many; links removed, never
followed."""

import os

import pytest

from volseg import _atomic


def _tree(root, files: int):
    """`files` files over three nested folders, a link to a folder outside and a
    link to a file outside; returns the outside folder and file."""
    outside = root.parent / f"outside-{root.name}"
    outside.mkdir()
    (outside / "kept").write_bytes(b"keep me")
    kept_file = root.parent / f"kept-{root.name}"
    kept_file.write_bytes(b"keep me too")
    for stage in ("stage0", "stage1"):
        (root / stage).mkdir()
    for i in range(files):
        folder = root / f"stage{i % 3}" / ("deep" if i % 2 else "")
        folder.mkdir(parents=True, exist_ok=True)
        (folder / f"{i}.npys").write_bytes(bytes(100 + i))
    (root / "stage0" / "to-folder").symlink_to(outside, target_is_directory=True)
    (root / "stage1" / "to-file").symlink_to(kept_file)
    return outside, kept_file


@pytest.mark.parametrize("files", [0, 3, _atomic._PARALLEL_FROM, 200])
def test_remove_tree_removes_all_and_follows_no_link(tmp_path, files, monkeypatch):
    unlinked = []
    real = _atomic._unlink
    monkeypatch.setattr(_atomic, "_unlink", lambda p: unlinked.append(p) or real(p))
    root = tmp_path / "work"
    root.mkdir()
    outside, kept_file = _tree(root, files)
    _atomic.remove_tree(root)
    assert not os.path.lexists(root)
    assert (outside / "kept").read_bytes() == b"keep me"
    assert kept_file.read_bytes() == b"keep me too"
    # Many files: each unlinked by the pool (the file link too; the folder link is
    # listed among the folders and removed by rmtree as a link); few: rmtree alone.
    assert len(unlinked) == (files + 1 if files + 1 >= _atomic._PARALLEL_FROM else 0)


def test_remove_tree_leaves_a_link_at_its_path_and_a_missing_path(tmp_path):
    target = tmp_path / "target"
    target.mkdir()
    (target / "a").write_bytes(b"a")
    link = tmp_path / "link"
    link.symlink_to(target, target_is_directory=True)
    _atomic.remove_tree(link)                    # as shutil.rmtree(..., ignore_errors=True)
    assert link.is_symlink() and (target / "a").read_bytes() == b"a"
    _atomic.remove_tree(tmp_path / "missing")    # nothing there: nothing done, no error
    _atomic.remove_tree(str(target))             # a str path too
    assert not target.exists()
