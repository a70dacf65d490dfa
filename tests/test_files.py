"""The one writer (verifier.files.atomic_write): atomic, mode-keeping, never replacing what is not a regular file."""

import os
import signal
import stat
import subprocess
import sys
import textwrap
import time

import pytest

from crosscert.robots.errors import InputError
from crosscert.verifier.files import atomic_write, check_output_path


def _text(s):
    return lambda fh: fh.write(s)


def test_a_new_file_follows_the_umask(tmp_path):
    old = os.umask(0o027)
    try:
        atomic_write(tmp_path / "new.csv", _text("a\n"))
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "new.csv").stat().st_mode) == 0o640
    assert (tmp_path / "new.csv").read_text() == "a\n"


def test_an_existing_file_keeps_its_mode(tmp_path):
    f = tmp_path / "old.csv"
    f.write_text("old")
    f.chmod(0o604)
    atomic_write(f, _text("new"))
    assert f.read_text() == "new" and stat.S_IMODE(f.stat().st_mode) == 0o604


def test_a_symlink_is_followed_and_kept(tmp_path):
    target = tmp_path / "real.csv"
    target.write_text("old")
    link = tmp_path / "link.csv"
    link.symlink_to(target)
    assert atomic_write(link, _text("new")) == target
    assert link.is_symlink() and target.read_text() == "new"


@pytest.mark.parametrize("path", ["/dev/null", "/dev/full"])
def test_a_device_is_refused_and_stays_a_device(path):
    if not os.path.exists(path):
        pytest.skip(f"{path} absent")
    with pytest.raises(InputError, match="not a regular file"):
        atomic_write(path, _text("x"))
    assert stat.S_ISCHR(os.stat(path).st_mode)


def test_a_directory_a_pipe_and_a_missing_folder_are_refused(tmp_path):
    with pytest.raises(InputError, match="is a directory"):
        check_output_path(tmp_path)
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    with pytest.raises(InputError, match="not a regular file"):
        check_output_path(fifo)
    with pytest.raises(InputError, match="does not exist"):
        check_output_path(tmp_path / "no" / "x.csv")
    with pytest.raises(InputError, match="empty path"):
        check_output_path("")


def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path):
    f = tmp_path / "keep.csv"
    f.write_text("old")

    def boom(fh):
        fh.write("partial")
        raise RuntimeError("disk full")

    with pytest.raises(RuntimeError):
        atomic_write(f, boom)
    assert f.read_text() == "old" and sorted(p.name for p in tmp_path.iterdir()) == ["keep.csv"]


def test_sigterm_during_a_write_leaves_no_temporary(tmp_path):
    """The process is killed politely while the content is being written: no hidden temporary remains."""
    script = textwrap.dedent(f"""
        import sys, time
        sys.path.insert(0, {os.getcwd()!r})
        from crosscert.verifier.files import atomic_write

        def slow(fh):
            fh.write("begin")
            fh.flush()
            print("writing", flush=True)
            time.sleep(30)

        atomic_write({str(tmp_path / "out.csv")!r}, slow)
    """)
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "writing"
    time.sleep(0.1)
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=30) == 128 + signal.SIGTERM
    assert list(tmp_path.iterdir()) == []
