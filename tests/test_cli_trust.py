"""The command line under hostile and careless use (issue 11): every bad input a clean
exit 2 with one line naming the problem, outputs written as a set or not at all."""

import gzip
import json
import os
import signal
import subprocess
import sys
import threading
import time
import tracemalloc

import nibabel
import numpy as np
import pytest

from volseg.cli import main
from volseg.io import OutputSet, VolumeFileError

ROTATED = np.array([[0.0, -2.0, 0.0, 10.0], [1.5, 0.0, 0.0, -3.0], [0.0, 0.0, -4.0, 7.0],
                    [0.0, 0.0, 0.0, 1.0]])
KINDS = ("labels.nii.gz", "curvature.nii.gz", "summary.json", "preview.png", "volumes.vti")
SET = [*(f"_{k}" for k in KINDS), "_segmentation.ome.zarr"]    # one output set's suffixes


def _blob(shape=(12, 10, 8)):
    x, y, z = np.meshgrid(*[np.linspace(-1, 1, s) for s in shape], indexing="ij")
    return np.round(200 * np.exp(-3 * ((x - 0.3) ** 2 + y**2 + z**2))
                    + 120 * np.exp(-4 * ((x + 0.4) ** 2 + (y - 0.2) ** 2 + z**2))).astype(np.uint8)


def _raw(path, data):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(np.ascontiguousarray(data.transpose(2, 1, 0)).tobytes())
    return path


def _one_clean_line(err):
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def _snapshot(folder):
    """Every file under `folder` (output sets hold folders: .ome.zarr) and its bytes."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file()}


def _visible(folder):
    return sorted(p.name for p in folder.iterdir() if not p.name.startswith(".")) \
        if folder.exists() else []


def test_outputs_keep_a_rotated_flipped_translated_frame(tmp_path):
    image = nibabel.Nifti1Image(_blob(), ROTATED)
    image.header.set_sform(ROTATED, 4)
    image.header.set_qform(ROTATED, 1)
    nibabel.save(image, tmp_path / "scan.nii.gz")
    assert main(["segment", str(tmp_path / "scan.nii.gz"), "-o", str(tmp_path / "out"), "-q",
                 "--regions", "2"]) == 0
    for kind in ("labels", "curvature"):
        out = nibabel.load(tmp_path / "out" / f"scan_{kind}.nii.gz")
        np.testing.assert_allclose(out.affine, ROTATED)
        assert (int(out.header["sform_code"]), int(out.header["qform_code"])) == (4, 1)
    summary = json.loads((tmp_path / "out" / "scan_summary.json").read_text())
    np.testing.assert_allclose(summary["affine"], ROTATED)
    assert summary["spacing"] == [1.5, 2.0, 4.0]


def test_nrrd_frame_reaches_the_nifti_outputs(tmp_path):
    header = ("NRRD0004\ntype: uchar\ndimension: 3\nspace: left-posterior-superior\n"
              "sizes: 12 10 8\nspace directions: (0,-1.5,0) (2,0,0) (0,0,-4)\n"
              "space origin: (-10,3,7)\nencoding: raw\n\n")
    (tmp_path / "s.nrrd").write_bytes(header.encode()
                                      + np.ascontiguousarray(_blob().transpose(2, 1, 0)).tobytes())
    assert main(["segment", str(tmp_path / "s.nrrd"), "-o", str(tmp_path), "-q"]) == 0
    np.testing.assert_allclose(nibabel.load(tmp_path / "s_labels.nii.gz").affine, ROTATED)


def test_detached_header_outside_its_folder_is_refused(tmp_path, capsys):
    secret = _raw(tmp_path / "private" / "secret.bin", _blob())
    header = tmp_path / "h" / "scan.nhdr"
    header.parent.mkdir()
    for name in [str(secret), "../private/secret.bin"]:
        header.write_text("NRRD0004\ntype: uchar\ndimension: 3\nsizes: 12 10 8\nencoding: raw\n"
                          f"data file: {name}\n")
        assert main(["segment", str(header), "-o", str(tmp_path / "out"), "-q"]) == 2
        line = _one_clean_line(capsys.readouterr().err)
        assert "scan.nhdr" in line and name in line and "--allow-external-data" in line
        assert _visible(tmp_path / "out") == []
    assert main(["segment", str(header), "-o", str(tmp_path / "out"), "-q",
                 "--allow-external-data"]) == 0
    summary = json.loads((tmp_path / "out" / "scan_summary.json").read_text())
    import hashlib

    expected = hashlib.sha256(header.read_bytes() + secret.read_bytes()).hexdigest()
    assert summary["input_sha256"] == expected  # every byte read: header and data
    assert summary["input_files"] == [str(header), str(header.parent / "../private/secret.bin")]


def test_two_inputs_with_one_output_stem_are_refused_before_computing(tmp_path, capsys):
    a = _raw(tmp_path / "a" / "s_12x10x8_uint8.raw", _blob())
    b = _raw(tmp_path / "b" / "s_12x10x8_uint8.raw", _blob()[::-1].copy())
    out = tmp_path / "out"
    assert main(["segment", "--force", "-o", str(out), str(a), str(b), "-q"]) == 2
    line = _one_clean_line(capsys.readouterr().err)
    assert str(a) in line and str(b) in line and "s_*" in line
    assert _visible(out) == [] and not out.exists() or not list(out.iterdir())


def test_existing_outputs_of_any_input_are_refused_up_front(tmp_path, capsys):
    a = _raw(tmp_path / "a_12x10x8_uint8.raw", _blob())
    b = _raw(tmp_path / "b_12x10x8_uint8.raw", _blob()[::-1].copy())
    out = tmp_path / "out"
    assert main(["segment", str(b), "-o", str(out), "-q", "--regions", "1"]) == 0
    before = _snapshot(out)
    assert main(["segment", str(a), str(b), "-o", str(out), "-q"]) == 2
    assert "b_labels.nii.gz exists" in _one_clean_line(capsys.readouterr().err)
    assert _snapshot(out) == before  # a's set not written


def test_a_second_writer_fails_at_once_or_waits(tmp_path, capsys, monkeypatch):
    source = _raw(tmp_path / "w_12x10x8_uint8.raw", _blob())
    out = tmp_path / "out"
    out.mkdir()
    names = {k: f"w_{k}" for k in ("labels.nii.gz",)}
    import fcntl

    calls, flock = [], fcntl.flock

    def recorded(fd, operation):
        calls.append(operation)
        return flock(fd, operation)

    monkeypatch.setattr(fcntl, "flock", recorded)       # the lock imports it when taken
    with OutputSet(out, "w", names):
        calls.clear()
        assert main(["segment", str(source), "-o", str(out), "-q"]) == 2
        # At once: the lock was tried without blocking.
        assert calls and all(op & fcntl.LOCK_NB for op in calls)
        assert "another volseg process is writing w_*" in _one_clean_line(capsys.readouterr().err)
    holder = OutputSet(out, "w", names)
    holder.acquire()
    released = threading.Event()

    def free():
        released.set()          # set first: the waiting run cannot finish before it
        holder.release()

    threading.Timer(0.5, free).start()
    assert main(["segment", str(source), "-o", str(out), "-q", "--wait"]) == 0
    assert released.is_set()    # it waited for the other writer's lock
    assert _visible(out) == sorted(f"w{e}" for e in SET)
    assert not [p for p in out.iterdir() if p.name.startswith(".")]  # lock and staging gone


def test_a_folder_in_place_of_an_output_is_refused_and_nothing_moves(tmp_path, capsys):
    source = _raw(tmp_path / "f_12x10x8_uint8.raw", _blob())
    out = tmp_path / "out"
    assert main(["segment", str(source), "-o", str(out), "-q"]) == 0
    (out / "f_preview.png").unlink()
    (out / "f_preview.png").mkdir()
    before = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()}
    assert main(["segment", str(source), "-o", str(out), "-q", "--force", "--regions", "1"]) == 2
    assert "f_preview.png: exists and is not a regular file" in capsys.readouterr().err
    assert {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()} == before


def test_a_failing_rename_rolls_back_to_the_complete_old_set(tmp_path, monkeypatch):
    import volseg.io.output_set as output_set

    source = _raw(tmp_path / "r_12x10x8_uint8.raw", _blob())
    out = tmp_path / "out"
    assert main(["segment", str(source), "-o", str(out), "-q"]) == 0
    before = _snapshot(out)
    real_replace, calls = os.replace, []

    def flaky(src, dst):
        calls.append(dst)
        if len(calls) == 6:  # 4 old files moved aside, 1 new one placed, then a failure
            raise OSError(28, "No space left on device", str(dst))
        return real_replace(src, dst)

    monkeypatch.setattr(output_set.os, "replace", flaky)
    assert main(["segment", str(source), "-o", str(out), "-q", "--force", "--regions", "1"]) == 2
    monkeypatch.undo()
    assert _snapshot(out) == before


@pytest.mark.parametrize("make, message", [
    (lambda d: "/dev/zero", "is a character device"),
    (lambda d: (os.mkfifo(d / "p_4x4x4_uint8.raw"), d / "p_4x4x4_uint8.raw")[1], "is a named pipe"),
    (lambda d: d / ("n" * 300 + ".raw"), "File name too long"),
    (lambda d: (d / "x.nii.gz").write_bytes(b"\x1f\x8b garbage") and d / "x.nii.gz", "x.nii.gz"),
    (lambda d: (d / "t.npy").write_bytes(b"\x93NUMPY\x01\x00\x10\x00{'descr': <f4 }\n")
     and d / "t.npy", "not a plain .npy array"),
    (lambda d: (d / "h.nrrd").write_bytes(b"NRRD0004\ntype: uchar\nsizes: 4 four 4\n\n")
     and d / "h.nrrd", "'sizes' field"),
])
def test_hostile_inputs_exit_2_with_one_line(tmp_path, make, message):
    # A subprocess, so a hang (a pipe opened for reading) fails the test instead of blocking it.
    target = make(tmp_path)
    run = subprocess.run([sys.executable, "-m", "volseg", "segment", str(target), "--shape",
                          "4", "4", "4", "-o", str(tmp_path / "out"), "-q"],
                         capture_output=True, text=True, timeout=60)
    assert run.returncode == 2, run.stderr
    assert message in _one_clean_line(run.stderr)
    assert _visible(tmp_path / "out") == []


def test_huge_declared_nifti_is_refused_fast(tmp_path):
    header = nibabel.Nifti1Header()
    header.set_data_shape((2000, 2000, 2000))
    header.set_data_dtype(np.float64)
    header["vox_offset"] = 352
    (tmp_path / "big.nii.gz").write_bytes(gzip.compress(header.binaryblock + bytes(4)))
    tracemalloc.start()      # bounded work: nothing near the declared 64 GB is allocated
    try:
        assert main(["segment", str(tmp_path / "big.nii.gz"), "-o", str(tmp_path), "-q"]) == 2
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 20 << 20, peak


def test_demo_needs_force_to_replace(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "-o", str(out), "-q"]) == 0
    assert main(["demo", "-o", str(out), "-q"]) == 2
    assert "use --force" in capsys.readouterr().err
    assert main(["demo", "-o", str(out), "-q", "--force"]) == 0


def test_summary_is_strict_json(tmp_path):
    source = _raw(tmp_path / "j_12x10x8_uint8.raw", _blob())
    assert main(["segment", str(source), "-o", str(tmp_path), "-q"]) == 0

    def refuse(token):
        raise ValueError(f"non-strict JSON token {token}")

    json.loads((tmp_path / "j_summary.json").read_text(), parse_constant=refuse)


def _segment_process(source, out):
    return subprocess.Popen([sys.executable, "-m", "volseg", "segment", str(source), "-o",
                             str(out), "-q", "--force"], stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)


@pytest.mark.slow
def test_sigterm_cleans_staging_and_releases_the_lock(tmp_path):
    source = _raw(tmp_path / "t_96x96x96_uint8.raw", _blob((96, 96, 96)))
    out = tmp_path / "out"
    process = _segment_process(source, out)
    deadline = time.monotonic() + 30
    while not (out.exists() and any(p.name.startswith(".t.") for p in out.iterdir())):
        assert time.monotonic() < deadline and process.poll() is None
        time.sleep(0.01)
    process.send_signal(signal.SIGTERM)
    _, err = process.communicate(timeout=30)
    assert process.returncode == 130
    assert "interrupted" in err
    assert not out.exists()  # no staging, no lock, no half set: the folder it made, gone


@pytest.mark.slow
def test_sigkill_at_random_moments_leaves_no_set_or_one_complete_set(tmp_path):
    from volseg.io import recover

    source = _raw(tmp_path / "k_24x24x24_uint8.raw", _blob((24, 24, 24)))
    complete = sorted(f"k{e}" for e in SET)
    # One whole run first: it fills numba's cache (a cold one makes every run slower
    # than any fixed kill time) and times a run, so the kills span it on any machine.
    started = time.perf_counter()
    timed = _segment_process(source, tmp_path / "timed")
    timed.communicate()
    assert timed.returncode == 0
    duration = time.perf_counter() - started
    rng = np.random.default_rng(7)
    outcomes, stale = [], []
    for run in range(20):
        out = tmp_path / f"out{run}"
        process = _segment_process(source, out)
        time.sleep(float(rng.uniform(0.15, 1.3)) * duration)
        process.kill()
        process.communicate()
        visible = _visible(out)
        hidden = [p for p in out.iterdir() if p.name.startswith(".")] if out.exists() else []
        if visible not in ([], complete):
            # Killed between the renames of a commit: its journal completes it.
            assert any((p / "COMMIT").exists() for p in hidden), visible
            recover(out, "k")
            visible = _visible(out)
        assert visible in ([], complete), visible
        outcomes.append(len(visible))
        if hidden:
            stale.append(out)
    assert 0 in outcomes and len(complete) in outcomes, outcomes  # before and after a commit
    assert stale  # some kills left a lock file or a staging folder behind ...
    for out in stale:  # ... which the next run in that folder removes
        assert main(["segment", str(source), "-o", str(out), "-q", "--force"]) == 0
        assert [p.name for p in out.iterdir() if p.name.startswith(".")] == []
        assert _visible(out) == complete


def _nifti_bytes(data, *, extension=None):
    image = nibabel.Nifti1Image(data, np.eye(4))
    if extension is not None:
        image.header.extensions.append(nibabel.nifti1.Nifti1Extension(6, extension))
    return bytearray(image.to_bytes())


def _patched(raw, at, fmt, value):
    import struct

    raw[at:at + struct.calcsize(fmt)] = struct.pack(fmt, value)
    return bytes(raw)


def _gzip_nrrd(dimension="3", cut=0):
    import gzip

    body = gzip.compress(np.ascontiguousarray(_blob().transpose(2, 1, 0)).tobytes())
    header = f"NRRD0004\ntype: uchar\ndimension: {dimension}\nsizes: 12 10 8\nencoding: gzip\n\n"
    return header.encode() + body[:len(body) - cut]


@pytest.mark.parametrize("name, content, message", [
    ("slope.nii", lambda: _patched(_nifti_bytes(_blob()), 112, "<f", float("inf")),
     "'scl_slope' field is inf"),
    ("ext.nii", lambda: _patched(_nifti_bytes(_blob(), extension=b"hello"), 352, "<i", 2**31 - 16),
     "extension"),
    ("cut.nii.gz", lambda: __import__("gzip").compress(bytes(_nifti_bytes(_blob())))[:-8],
     "ends before its gzip trailer"),
    ("dim.nrrd", lambda: _gzip_nrrd(dimension="2"), "'dimension' field says 2 but 'sizes' lists 3"),
    ("cut.nrrd", lambda: _gzip_nrrd(cut=8), "ends before its gzip trailer"),
])
def test_inconsistent_headers_and_truncated_streams_exit_2_with_one_line(tmp_path, capsys, name,
                                                                        content, message):
    (tmp_path / name).write_bytes(content())
    assert main(["segment", str(tmp_path / name), "-o", str(tmp_path / "out"), "-q"]) == 2
    line = _one_clean_line(capsys.readouterr().err)
    assert message in line and name in line
    assert _visible(tmp_path / "out") == []


def test_an_input_rewritten_during_the_run_is_refused_and_nothing_written(tmp_path, capsys,
                                                                          monkeypatch):
    import volseg.files as files

    source = _raw(tmp_path / "r_12x10x8_uint8.raw", _blob())
    real = files.run_stages

    def rewritten(*args, **kwargs):
        result = real(*args, **kwargs)
        source.write_bytes(source.read_bytes()[::-1])       # another process's new version
        return result

    monkeypatch.setattr(files, "run_stages", rewritten)
    assert main(["segment", str(source), "-o", str(tmp_path / "out"), "-q", "--regions",
                 "1"]) == 2
    line = _one_clean_line(capsys.readouterr().err)
    assert "changed while volseg read it" in line and source.name in line
    assert _visible(tmp_path / "out") == []
    monkeypatch.undo()
    assert main(["segment", str(source), "-o", str(tmp_path / "out"), "-q"]) == 0


@pytest.mark.parametrize("argv, message", [
    (["--memory-limit", "inf"], "--memory-limit must be a positive finite size"),
    (["--memory-limit", "nan"], "--memory-limit must be a positive finite size"),
    (["--scheduler", "tls://127.0.0.1:1"], "cannot reach the Dask scheduler"),
])
def test_bad_engine_options_exit_2_even_for_an_in_memory_input(tmp_path, capsys, argv, message):
    source = _raw(tmp_path / "e_12x10x8_uint8.raw", _blob())
    assert main(["segment", str(source), "-o", str(tmp_path / "out"), "-q", *argv]) == 2
    assert message in _one_clean_line(capsys.readouterr().err)
    assert _visible(tmp_path / "out") == []


@pytest.mark.slow
def test_a_scheduler_that_accepts_and_never_answers_is_given_up(tmp_path):
    import socket
    import time

    from volseg.blockwise.engine import Engine
    from volseg.errors import EngineError

    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(5)
    address = "tcp://127.0.0.1:%d" % server.getsockname()[1]
    started = time.monotonic()
    with pytest.raises(EngineError, match="no answer within 0.5 s"):
        Engine(address, timeout=0.5).check()
    assert time.monotonic() - started < 20
    server.close()


def test_odd_zarr_metadata_and_arguments_are_refused_by_name(tmp_path, capsys):
    import zarr

    from volseg.io import read_volume

    store = zarr.create_array(str(tmp_path / "a.zarr"), shape=(8, 8, 8), chunks=(4, 4, 4),
                              dtype="uint8", config={"write_empty_chunks": True})
    store[:] = 1
    store.attrs["volseg"] = "xyz"
    assert main(["info", str(tmp_path / "a.zarr")]) == 2
    assert "'volseg' attribute must be an object" in _one_clean_line(capsys.readouterr().err)
    group = zarr.open_group(str(tmp_path / "g.zarr"), mode="w")
    group.create_group("0")
    group.attrs["multiscales"] = [{"axes": ["z", "y", "x"], "datasets": [{"path": "0"}]}]
    assert main(["info", str(tmp_path / "g.zarr")]) == 2
    assert "is a group, not an array" in _one_clean_line(capsys.readouterr().err)
    with pytest.raises(ValueError, match="`chunks` must be a positive whole number"):
        read_volume(_raw(tmp_path / "c_12x10x8_uint8.raw", _blob()), chunks=0)


@pytest.mark.parametrize("value, message", [
    (np.nan, "holds NaN or infinite values (its range is nan .. nan)"),
    (np.inf, "holds NaN or infinite values"),
])
def test_a_store_with_nan_or_inf_says_so(tmp_path, capsys, value, message):
    from volseg.io import write_zarr

    data = np.random.default_rng(0).random((20, 20, 20)).astype(np.float32)
    data[3, 4, 5] = value
    write_zarr(tmp_path / "v.zarr", data, chunks=(8, 8, 8))
    assert main(["segment", str(tmp_path / "v.zarr"), "-o", str(tmp_path / "out"), "-q"]) == 2
    line = _one_clean_line(capsys.readouterr().err)
    assert message in line and "v.zarr" in line and "mask" not in line
    assert _visible(tmp_path / "out") == []


def test_denormal_values_ask_for_a_value_scale(tmp_path, capsys):
    np.save(tmp_path / "d.npy", np.random.default_rng(0).random((12, 10, 8)) * 1e-310)
    assert main(["segment", str(tmp_path / "d.npy"), "-o", str(tmp_path / "out"), "-q"]) == 2
    line = _one_clean_line(capsys.readouterr().err)
    assert "give one (value_scale, --value-scale)" in line and "d.npy" in line
    assert main(["segment", str(tmp_path / "d.npy"), "-o", str(tmp_path / "out"), "-q",
                 "--value-scale", "1e308"]) == 0


def test_api_edges_name_their_argument(tmp_path):
    from volseg.io import read_volume, write_volume
    from volseg.morse import descending_complex

    with pytest.raises(ValueError, match="`field` is a single number"):
        descending_complex(np.array(3.0))
    hierarchy = descending_complex(np.random.default_rng(0).random(50))
    for bad in ((40, 20), (-5, 3), ("a", 3)):
        with pytest.raises(ValueError, match="`region_range`"):
            hierarchy.largest_gap(bad)
    mask = np.zeros((4, 5, 6), bool)
    mask[1:3, 2:4, 3:5] = True
    write_volume(tmp_path / "m.nii.gz", mask)
    back = np.asarray(read_volume(tmp_path / "m.nii.gz").data)
    assert back.dtype == np.uint8 and np.array_equal(back, mask)


def test_budget_and_shape_limits_say_why(tmp_path, capsys):
    import gzip

    from volseg.io import read_volume

    (tmp_path / "g.nii.gz").write_bytes(gzip.compress(bytes(_nifti_bytes(_blob()))))
    assert main(["segment", str(tmp_path / "g.nii.gz"), "-o", str(tmp_path / "o"), "-q",
                 "--memory-limit", "20KB"]) == 2
    assert "is read whole and needs about" in _one_clean_line(capsys.readouterr().err)
    (tmp_path / "flat.nrrd").write_bytes(b"NRRD0004\ntype: uchar\ndimension: 2\nsizes: 4 5\n"
                                         b"encoding: raw\n\n" + bytes(20))
    assert main(["info", str(tmp_path / "flat.nrrd")]) == 2
    assert "a 2-D NRRD (sizes 4 5); volseg segments 3-D" in _one_clean_line(
        capsys.readouterr().err)
    source = _raw(tmp_path / "c_12x10x8_uint8.raw", _blob())
    assert main(["segment", str(source), "-o", str(tmp_path / "o"), "-q", "--scheduler",
                 "local", "--workers", "1", "--memory-limit", "1MB", "--chunks", "8"]) == 2
    assert "a worker needs to make progress" in _one_clean_line(capsys.readouterr().err)
    lazy = read_volume(source, chunks=4)
    source.write_bytes(source.read_bytes()[:100])          # truncated while it is read
    with pytest.raises(VolumeFileError, match="truncated or replaced while volseg read it"):
        lazy.data.compute()


def test_a_full_disk_names_the_folder_and_the_rerun_resumes(tmp_path, capsys, monkeypatch):
    """ENOSPC in the middle of the blockwise work: one line naming the output folder,
    nothing committed, the finished blocks kept; the rerun (space freed) finishes with
    the labels of a run that never failed."""
    import errno

    from volseg.blockwise import _resume

    data = _blob((20, 18, 16))
    source = _raw(tmp_path / "v_20x18x16_uint8.raw", data)
    argv = ["segment", str(source), "-q", "--chunks", "8", "--regions", "3"]
    assert main([*argv, "-o", str(tmp_path / "clean")]) == 0
    written = []
    real = _resume.write_atomically

    def fills_up(path, *args, **kwargs):
        if len(written) == 5:
            raise OSError(errno.ENOSPC, "No space left on device")
        written.append(path)
        return real(path, *args, **kwargs)

    monkeypatch.setattr(_resume, "write_atomically", fills_up)
    capsys.readouterr()
    assert main([*argv, "-o", str(tmp_path / "out")]) == 2
    line = _one_clean_line(capsys.readouterr().err)
    assert str(tmp_path / "out") in line and "disk is full" in line
    assert _visible(tmp_path / "out") == []
    assert len(list((tmp_path / "out" / ".v.volseg-work").rglob("*.npys"))) == 5
    monkeypatch.setattr(_resume, "write_atomically", real)
    assert main([*argv, "-o", str(tmp_path / "out")]) == 0
    labels = [nibabel.load(tmp_path / f / "v_labels.nii.gz").get_fdata() for f in ("clean", "out")]
    np.testing.assert_array_equal(*labels)
    assert not (tmp_path / "out" / ".v.volseg-work").exists()


def test_lengths_that_would_overflow_the_operators_are_refused(tmp_path, capsys):
    """Voxel sizes and time steps of 1e300 overflowed inside the curvature (45
    RuntimeWarnings, then 'simplices have zero volume'); 1e-300 divided by zero. Inside
    [1e-30, 1e30] the run is clean, warnings as errors; a NIfTI's (float32) 1e31 is
    refused with its file name."""
    import warnings

    from volseg import segment_volume

    data = _blob((10, 9, 8))
    for spacing in (1e300, 1e-300, (1.0, 1e31, 1.0)):
        with pytest.raises(ValueError, match=r"`spacing` must be three numbers .* in \[1e-30"):
            segment_volume(data, spacing=spacing, n_regions=2)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for spacing in (1e30, 1e-30, (1e-30, 1e30, 1.0)):
            assert segment_volume(data, spacing=spacing, n_regions=2,
                                  smooth_sigma=0).labels.max() == 2
    image = nibabel.Nifti1Image(data, np.diag([1e31, 1e31, 1e31, 1.0]))
    nibabel.save(image, tmp_path / "huge.nii.gz")
    assert main(["segment", str(tmp_path / "huge.nii.gz"), "-o", str(tmp_path / "o")]) == 2
    line = _one_clean_line(capsys.readouterr().err)
    assert "huge.nii.gz: voxel sizes must be in [1e-30, 1e+30]" in line
    series = np.stack([data.astype(np.float32)] * 3, axis=-1)
    np.save(tmp_path / "t.npy", series)
    for scale in ("1e300", "1e-300", "0", "nan"):
        assert main(["isosurface", str(tmp_path / "t.npy"), "--level", "100", "-o",
                     str(tmp_path / "o"), "--time-scale", scale]) == 2
        assert "`--time-scale` must be a" in _one_clean_line(capsys.readouterr().err)
    assert _visible(tmp_path / "o") == []


def test_force_leaves_no_file_of_the_old_run_beside_the_new_set(tmp_path, capsys):
    """Issue 57's case: --chunks 16 --regions 7 --plot-persistence, then --force --regions
    12 --no-vti; the old .zarr stores, .vti and persistence plot were left beside the new
    set (and a reader of the folder saw the old labels). The same here on a small
    volume, the new run with another field: only the new set is there; without
    --force, any file of the stem's sets is refused."""
    source = tmp_path / "s.npy"
    np.save(source, np.repeat(_blob((16, 14, 12)), 2, axis=0))
    out = tmp_path / "out"
    assert main(["segment", str(source), "-o", str(out), "-q", "--chunks", "8",
                 "--regions", "3", "--plot-persistence"]) == 0
    old = {p.name for p in out.iterdir() if not p.name.startswith(".")}
    assert {"s_labels.zarr", "s_curvature.zarr", "s_persistence.png"} <= old
    assert main(["segment", str(source), "-o", str(out), "-q", "--regions", "2", "--no-vti",
                 "--field", "gradient"]) == 2          # the old set's files: refused
    assert "exists" in capsys.readouterr().err
    assert main(["segment", str(source), "-o", str(out), "-q", "--force", "--regions", "2",
                 "--no-vti", "--field", "gradient"]) == 0
    new = {p.name for p in out.iterdir() if not p.name.startswith(".")}
    assert new == {"s_labels.nii.gz", "s_gradient.nii.gz", "s_segmentation.ome.zarr",
                   "s_summary.json", "s_preview.png"}, new


def test_a_bool_volume_is_refused_and_leaves_no_folder(tmp_path, capsys):
    """A boolean .npy is a mask or a label map, not an image (issue 57, #13): exit 2,
    a message naming the file, and no output folder (nor work folder) left behind."""
    np.save(tmp_path / "b.npy", np.random.default_rng(0).random((9, 9, 9)) > 0.5)
    for extra in ([], ["--chunks", "4"]):
        out = tmp_path / f"out{len(extra)}"
        assert main(["segment", str(tmp_path / "b.npy"), "-o", str(out), *extra]) == 2
        assert "holds booleans" in capsys.readouterr().err
        assert not out.exists()
    kept = tmp_path / "kept"
    kept.mkdir()
    assert main(["segment", str(tmp_path / "b.npy"), "-o", str(kept)]) == 2
    assert kept.is_dir() and not any(kept.iterdir())


def test_chunks_on_an_axis_shorter_than_the_halo_equal_in_memory(tmp_path):
    """A 3-voxel axis in 2-voxel chunks under a smoothing halo of 4: that axis is one
    block (Dask cut no halo deeper than the array), the labels equal in memory."""
    rng = np.random.default_rng(0)
    np.save(tmp_path / "thin.npy", rng.integers(0, 255, (20, 18, 3)).astype(np.uint8))
    for name, extra in (("mem", []), ("blocks", ["--chunks", "2"])):
        assert main(["segment", str(tmp_path / "thin.npy"), "-o", str(tmp_path / name),
                     "-q", "--regions", "6", "--no-vti", *extra]) == 0
    a, b = (np.asarray(nibabel.load(tmp_path / n / "thin_labels.nii.gz").dataobj)
            for n in ("mem", "blocks"))
    np.testing.assert_array_equal(a, b)


def test_an_oblique_inputs_ome_zarr_placement_is_said(tmp_path, capsys):
    """NGFF 0.5 holds no rotation or flip (issue 58): the summary and stderr say the
    OME-Zarr image is placed axis-aligned; an axis-aligned input's is exact."""
    volume = np.random.default_rng(0).integers(0, 255, (16, 14, 12)).astype(np.uint8)
    rotated = np.array([[0, -1.5, 0, 10], [1, 0, 0, -5], [0, 0, 2, 3], [0, 0, 0, 1.0]])
    for name, affine in (("rot", rotated), ("flat", np.diag([1.0, 1.5, 2.0, 1.0]))):
        nibabel.save(nibabel.Nifti1Image(volume, affine), tmp_path / f"{name}.nii.gz")
        assert main(["segment", str(tmp_path / f"{name}.nii.gz"), "-o", str(tmp_path / name),
                     "--regions", "5", "--no-vti"]) == 0
        err = capsys.readouterr().err
        placement = json.loads((tmp_path / name / f"{name}_summary.json").read_text())[
            "ome_zarr_placement"]
        if name == "rot":
            assert placement.startswith("axis-aligned") and "placed axis-aligned" in err
        else:
            assert placement == "exact" and "axis-aligned" not in err


def test_a_smoothing_wider_than_the_volume_is_refused_at_once(tmp_path, capsys):
    """--smooth 1e6 on a 41^3 volume ran for hours (issue 57, #7); smooth_sigma=1e9 was
    a bare MemoryError. Both are refused before any work, naming the bound."""
    from volseg import segment_volume

    volume = np.random.default_rng(0).integers(0, 255, (41, 41, 41)).astype(np.uint8)
    np.save(tmp_path / "v.npy", volume)
    assert main(["segment", str(tmp_path / "v.npy"), "-o", str(tmp_path / "o"),
                 "--smooth", "1e6"]) == 2
    assert "use at most 41" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()
    with pytest.raises(ValueError, match="wider than"):
        segment_volume(volume, smooth_sigma=1e9)
