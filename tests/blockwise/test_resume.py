"""The work folder of a blockwise run (`volseg.blockwise.WorkFolder`): blocks kept for
the same key only, written atomically, read back as a lazy array, removed whole."""

import numpy as np
import pytest

from volseg.blockwise import WorkFolder


def test_work_folder_keeps_blocks_for_the_same_key_only(tmp_path):
    calls = []

    def block(x, block_id=None):
        calls.append(block_id)
        return x * 2, x.sum()

    work = WorkFolder(tmp_path / "w", {"input": "abc", "scale": 1.0})
    assert not work.resumed
    first = work.wrap("stage", block)(np.arange(3), block_id=(0, 1, 2))
    again = WorkFolder(tmp_path / "w", {"input": "abc", "scale": 1.0})
    second = again.wrap("stage", block)(np.arange(3), block_id=(0, 1, 2))
    assert again.resumed and again.finished("stage") == 1 and len(calls) == 1
    assert all(np.array_equal(a, b) for a, b in zip(first, second, strict=True))
    other = WorkFolder(tmp_path / "w", {"input": "abc", "scale": 2.0})   # another run
    assert not other.resumed and other.finished("stage") == 0


def test_a_block_killed_while_written_does_not_count_as_finished(tmp_path, monkeypatch):
    # Killed after the temporary file is written, before its rename: no block looks
    # finished (the count decides whether a stored stage is computed again). A kill
    # runs no clean-up: the temporary's removal is disabled too.
    import volseg._atomic as atomic

    work = WorkFolder(tmp_path / "w", {"input": "abc"})

    def killed(*args):
        raise KeyboardInterrupt

    monkeypatch.setattr(atomic.os, "replace", killed)
    monkeypatch.setattr(atomic.os, "unlink", lambda path: None)
    with pytest.raises(KeyboardInterrupt):
        work.wrap("stage", lambda x, block_id=None: x * 2)(np.arange(3), block_id=(0, 0, 0))
    assert len(list((work.folder / "stage").iterdir())) == 1       # the leftover
    assert work.finished("stage") == 0


def test_stored_blocks_read_back_as_the_array_they_were(tmp_path):
    import dask.array as da

    data = np.arange(6 * 5 * 4, dtype=np.float64).reshape(6, 5, 4)
    lazy = da.from_array(data, chunks=(4, 3, 4))
    work = WorkFolder(tmp_path / "w", {"input": "abc"})
    stored = lazy.map_blocks(work.wrap("stage", lambda x, block_id=None: x + 1),
                             dtype=np.float64).compute()
    assert np.array_equal(stored, data + 1)
    assert work.finished("stage") == lazy.npartitions
    again = work.array("stage", lazy.chunks, np.float64)
    assert np.array_equal(again.compute(), data + 1)
    work.remove()
    assert not work.folder.exists()


def test_blocks_read_back_exactly_whatever_their_arrays(tmp_path):
    """A block's arrays come back from its file with their dtypes, shapes, memory
    order and values: 0-d and empty arrays, booleans, a Fortran-ordered array, a
    tuple of one array (not the array), a single array (not a tuple)."""
    from volseg.blockwise import _resume

    rng = np.random.default_rng(3)
    fortran = np.asfortranarray(rng.standard_normal((3, 4, 5)).astype(np.float32))
    results = {(0, 0, 0): (np.int64(7), np.zeros((0, 3), dtype=np.int32), rng.random(6) > 0.5,
                           fortran, np.array([-np.inf, np.inf, -0.0])),
               (0, 0, 1): (np.arange(4, dtype=np.uint16),),
               (0, 0, 2): fortran}
    work = WorkFolder(tmp_path / "w", {"input": "abc"})
    for block_id in results:
        work.wrap("stage", lambda block_id=None: results[block_id])(block_id=block_id)
    _resume._CHECKED.clear()                                  # read as another process
    never = work.wrap("stage", lambda block_id=None: pytest.fail("computed again"))
    for block_id, result in results.items():
        got = never(block_id=block_id)
        assert isinstance(got, tuple) == isinstance(result, tuple)
        for a, b in zip(got if isinstance(got, tuple) else (got,),
                        result if isinstance(result, tuple) else (result,), strict=True):
            b = np.asarray(b)
            assert a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a, b)
            assert np.array_equal(np.signbit(a), np.signbit(b)) if a.dtype.kind == "f" else True
        assert never(block_id=block_id) is not None
    assert np.load(tmp_path / "w" / "stage" / "0_0_2.npys").shape == (32,)   # the digest


def test_a_block_not_in_the_folder_is_an_error_naming_it(tmp_path):
    import dask.array as da

    lazy = da.zeros((4, 4, 4), chunks=2)
    work = WorkFolder(tmp_path / "w", {"input": "abc"})
    with pytest.raises(RuntimeError, match=r"block \(\d, \d, \d\) was expected in the work folder"):
        work.array("never", lazy.chunks, np.float64).compute()


@pytest.mark.parametrize("torn", [b"", b"\x93NUMPY torn", "truncated", "cut in a header",
                                  "trailing bytes", "no arrays", "one array short",
                                  "an object array", "an old zip"])
def test_a_torn_block_is_computed_again_not_fatal(tmp_path, torn):
    calls = []

    def block(x, block_id=None):
        calls.append(block_id)
        return x * 2, x.sum()

    work = WorkFolder(tmp_path / "w", {"input": "abc"})
    expected = work.wrap("stage", block)(np.arange(50), block_id=(0, 0, 0))
    path = tmp_path / "w" / "stage" / "0_0_0.npys"
    whole = path.read_bytes()
    digest = np.load(path)
    if torn == "truncated":          # the last array short of its bytes
        torn = whole[:-9]
    elif torn == "cut in a header":
        torn = whole[:len(digest.tobytes()) + 140]
    elif torn == "trailing bytes":
        torn = whole + b"\0"
    elif torn in ("no arrays", "one array short", "an object array", "an old zip"):
        with open(path, "wb") as file:
            if torn == "an old zip":             # what earlier versions wrote there
                np.savez(file, item0=np.arange(50) * 2, item1=np.array(1225), _digest=digest)
            else:
                np.save(file, digest)
                np.save(file, np.array([0 if torn == "no arrays" else 2]))
                np.save(file, np.arange(50) * 2 if torn == "one array short"
                        else np.array([None, 1], dtype=object), allow_pickle=True)
        torn = path.read_bytes()
    path.write_bytes(torn)           # what a power loss or a full disk leaves
    again = WorkFolder(tmp_path / "w", {"input": "abc"})
    got = again.wrap("stage", block)(np.arange(50), block_id=(0, 0, 0))
    assert len(calls) == 2                                   # computed again
    assert all(np.array_equal(a, b) for a, b in zip(expected, got, strict=True))
    assert path.read_bytes() == whole                        # and saved whole


def test_a_planted_block_of_other_values_is_computed_again(tmp_path):
    """Issue 57, #8: a valid block with other values (another run's, another place's,
    or forged without the run's key) is not reused: its digest is not its own."""
    calls = []

    def block(x, block_id=None):
        calls.append(block_id)
        return x * 2

    work = WorkFolder(tmp_path / "w", {"input": "abc"})
    expected = work.wrap("stage", block)(np.arange(5), block_id=(0, 0, 0))
    path = tmp_path / "w" / "stage" / "0_0_0.npys"
    digest = np.load(path)
    with open(path, "wb") as file:                         # a valid block, other values
        for array in (digest, np.array([-1]), np.full(5, 7)):
            np.save(file, array)
    again = WorkFolder(tmp_path / "w", {"input": "abc"})
    assert np.array_equal(again.wrap("stage", block)(np.arange(5), block_id=(0, 0, 0)),
                          expected)
    assert len(calls) == 2
    # A block saved for another place is not taken for this one.
    moved = tmp_path / "w" / "stage" / "1_0_0.npys"
    path.rename(moved)
    assert np.array_equal(again.wrap("stage", block)(np.arange(5) + 1, block_id=(1, 0, 0)),
                          (np.arange(5) + 1) * 2)
    assert len(calls) == 3


def test_a_planted_link_is_removed_never_followed(tmp_path):
    """A link at a stage folder would make the run write where it points: the work
    folder holding one is emptied (the link removed, its target untouched)."""
    outside = tmp_path / "outside"
    outside.mkdir()
    work = WorkFolder(tmp_path / "w", {"input": "abc"})
    work.wrap("stage", lambda x, block_id=None: x)(np.arange(3), block_id=(0, 0, 0))
    (tmp_path / "w" / "linked").symlink_to(outside, target_is_directory=True)
    again = WorkFolder(tmp_path / "w", {"input": "abc"})
    assert not again.resumed and again.finished("stage") == 0
    assert not (tmp_path / "w" / "linked").exists()
    again.wrap("linked", lambda x, block_id=None: x)(np.arange(3), block_id=(0, 0, 0))
    assert list(outside.iterdir()) == []
    whole = tmp_path / "w2"
    whole.symlink_to(outside, target_is_directory=True)      # the folder itself a link
    fresh = WorkFolder(whole, {"input": "abc"})
    assert not whole.is_symlink() and not fresh.resumed and list(outside.iterdir()) == []


def test_a_block_is_digested_once_per_process_and_its_file(tmp_path, monkeypatch):
    """The digest of a saved block is computed when it is written and not again when
    this process reads the same file back (a run reads each block several times); a
    process that has not checked it (a resumed run, a worker) checks it once, and a
    file replaced at the path (another inode, size or change time) is checked again."""
    from volseg.blockwise import _resume

    digests = []
    real = _resume._digest

    def counted(tag, items):
        digests.append(tag)
        return real(tag, items)

    monkeypatch.setattr(_resume, "_digest", counted)
    work = WorkFolder(tmp_path / "w", {"input": "abc"})
    computed = []
    block = work.wrap("stage", lambda x, block_id=None: computed.append(1) or x * 2)
    expected = block(np.arange(50), block_id=(0, 0, 0))
    assert len(digests) == 1                                          # written
    for _ in range(3):
        assert np.array_equal(block(np.arange(50), block_id=(0, 0, 0)), expected)
    assert len(digests) == 1 and len(computed) == 1                   # read, not digested
    _resume._CHECKED.clear()                                          # another process
    assert np.array_equal(block(np.arange(50), block_id=(0, 0, 0)), expected)
    block(np.arange(50), block_id=(0, 0, 0))
    assert len(digests) == 2 and len(computed) == 1                   # checked once
    # The same file replaced by another block's (a copy: a new inode): checked again,
    # and refused, as its digest is of another place.
    path = tmp_path / "w" / "stage" / "0_0_0.npys"
    other = block(np.arange(50) + 1, block_id=(1, 0, 0))
    (tmp_path / "w" / "stage" / "1_0_0.npys").rename(path)
    assert np.array_equal(block(np.arange(50), block_id=(0, 0, 0)), expected)
    assert len(computed) == 3 and not np.array_equal(other, expected)
    work.remove()
    assert not any(p.startswith(str(tmp_path)) for p in _resume._CHECKED)
