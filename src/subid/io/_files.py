"""Every file subid reads or writes goes through this module.

Reading: :func:`open_regular` / :func:`read_regular` open regular files only
(a FIFO, a device, a socket or a directory is refused before anything is
read: a FIFO would block forever, ``/dev/zero`` would fill memory), check the
size against the caller's limit and read at most that many bytes. Writing:
:func:`atomic_write` replaces a file only when the new content is complete,
and :func:`atomic_directory` replaces a whole output folder at once.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import errno
import io
import os
import re
import secrets
import shutil
import stat

from subid.errors import DataFileNotFoundError, FileReadError, FileWriteError

try:
    import fcntl
except ImportError:                  # Windows: no FIFOs to guard against
    fcntl = None  # type: ignore[assignment]  # tested as `fcntl is None` where used

#: Default largest file a loader reads whole (model JSON, checkpoints, MAT files).
MAX_FILE_BYTES = 4 * 2**30
#: Default largest total of decompressed array bytes beyond the file's own
#: size (a compressed ``.npz``/``.mat`` member may expand to this much).
MAX_EXPANDED_BYTES = 1 * 2**30

_KINDS = ((stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISCHR, "a character device"),
          (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"),
          (stat.S_ISDIR, "a directory"))


def _shown(path) -> str:
    if isinstance(path, bytes):
        path = os.fsdecode(path)
    try:
        return os.fspath(path)
    except TypeError:
        raise FileReadError(f"a file name must be a str or os.PathLike, got "
                            f"{type(path).__name__}") from None


class _SizedFile(io.FileIO):
    """A regular file that must end where it ended when it was opened.

    Every reader of subid reads through it (:func:`open_regular`): a read
    that meets the end of the file before the size found on opening raises
    ``error`` (the file was truncated, or replaced by a shorter one, while it
    was read), so no reader can return a silently shorter record.
    """

    def __init__(self, fd: int, size: int, shown: str, what: str, error):
        super().__init__(fd, "rb", closefd=True)
        self._size, self._shown, self._what, self._error = size, shown, what, error

    def _check_end(self) -> None:
        if self.tell() < self._size:
            raise self._error(f"{self._shown} was truncated while it was read: it ended at "
                              f"byte {self.tell()} of the {self._size} it had when opened; "
                              f"read the {self._what} again when nothing writes to it",
                              path=self._shown)

    def readinto(self, buffer):
        count = super().readinto(buffer)
        if count == 0 and len(buffer):
            self._check_end()
        return count

    def read(self, size=-1):
        data = super().read(size)
        if not data and size != 0:
            self._check_end()
        return data

    def readall(self):
        data = super().readall()
        self._check_end()
        return data


def open_regular(path, *, what: str = "file", max_bytes: int | None = MAX_FILE_BYTES,
                 error=FileReadError):
    """Open ``path`` for binary reading if it is a regular file of at most ``max_bytes``.

    Returns ``(file object, size in bytes)``. Raises
    :class:`~subid.errors.DataFileNotFoundError` for a missing file and
    ``error`` (a :class:`~subid.errors.FileReadError` class) for anything
    else: a FIFO, device, socket or directory, a file larger than
    ``max_bytes``, a path holding a NUL byte, a permission problem.
    """
    shown = _shown(path)
    if "\x00" in shown:
        raise error(f"the {what} name {shown!r} holds a NUL byte, which no file name can "
                    "contain", path=shown.replace("\x00", "\\0"))
    try:
        # O_NONBLOCK: opening a FIFO without a writer would otherwise block forever.
        fd = os.open(shown, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0)
                     | getattr(os, "O_NOCTTY", 0) | getattr(os, "O_CLOEXEC", 0)
                     | getattr(os, "O_BINARY", 0))
    except FileNotFoundError:
        raise DataFileNotFoundError(f"no such file: {shown}", path=shown) from None
    except IsADirectoryError:
        raise error(f"{shown} is a directory, not a {what}", path=shown) from None
    except OSError as exc:
        raise error(f"cannot open the {what} {shown}: {exc.strerror or exc}",
                    path=shown) from None
    try:
        st = os.fstat(fd)
        for test, kind in _KINDS:
            if test(st.st_mode):
                raise error(f"{shown} is {kind}, not a regular {what}; subid reads regular "
                            "files only (copy the data to a file first)", path=shown)
        if not stat.S_ISREG(st.st_mode):
            raise error(f"{shown} is not a regular {what}", path=shown)
        if max_bytes is not None and st.st_size > max_bytes:
            raise error(f"{shown} is {st.st_size} bytes, more than the {max_bytes} bytes "
                        f"allowed for a {what} (max_bytes); pass a larger max_bytes if the "
                        "file is genuine", path=shown)
        if fcntl is not None:
            flags = fcntl.fcntl(fd, fcntl.F_GETFL)
            fcntl.fcntl(fd, fcntl.F_SETFL, flags & ~os.O_NONBLOCK)
        fh = io.BufferedReader(_SizedFile(fd, st.st_size, shown, what, error))
    except BaseException:
        os.close(fd)
        raise
    return fh, st.st_size


def read_regular(path, *, what: str = "file", max_bytes: int | None = MAX_FILE_BYTES,
                 error=FileReadError) -> bytes:
    """The bytes of a regular file of at most ``max_bytes`` (see :func:`open_regular`).

    At most ``max_bytes`` (or the size found on opening) plus one bytes are
    read, so a file that grows while it is read cannot exhaust memory.
    """
    fh, size = open_regular(path, what=what, max_bytes=max_bytes, error=error)
    shown = _shown(path)
    limit = size                       # never more than the size found on opening
    with fh:
        try:
            raw = fh.read(limit + 1)
        except OSError as exc:
            raise error(f"cannot read the {what} {shown}: {exc.strerror or exc}",
                        path=shown) from None
    if len(raw) > limit:
        raise error(f"{shown} grew while it was read (from {size} bytes); read it again "
                    "when it is complete", path=shown)
    return raw


def _fsync_directory(directory: str) -> None:
    """Make a rename durable (POSIX); ignored where directories cannot be opened."""
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _pid_alive(pid: int) -> bool:
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


_TEMP_RE = re.compile(r"^\.(?P<base>.+)\.(?P<pid>\d+)-[0-9a-f]{16}\.(tmp|staging|old)$")


def _temp_name(path: str, kind: str = "tmp") -> str:
    directory = os.path.dirname(os.path.abspath(path))
    return os.path.join(directory, f".{os.path.basename(path)}.{os.getpid()}-"
                                   f"{secrets.token_hex(8)}.{kind}")


def remove_stale_temporaries(path) -> list[str]:
    """Delete temporary files/folders left next to ``path`` by killed saves.

    A temporary name holds the writer's process id; those of processes that
    no longer run are removed. Returns the removed paths.
    """
    path = os.path.abspath(os.fspath(path))
    directory, base = os.path.split(path)
    removed: list[str] = []
    try:
        names = os.listdir(directory)
    except OSError:
        return removed
    for name in names:
        found = _TEMP_RE.match(name)
        if not found or found.group("base") != base or _pid_alive(int(found.group("pid"))):
            continue
        full = os.path.join(directory, name)
        try:
            if os.path.isdir(full) and not os.path.islink(full):
                shutil.rmtree(full)
            else:
                os.unlink(full)
            removed.append(full)
        except OSError:
            pass
    return removed


def _write_error(exc: OSError, path: str, what: str) -> FileWriteError:
    reason = exc.strerror or str(exc)
    hint = ""
    if exc.errno == errno.ENOSPC:
        hint = "; free some space and run again (the previous content is unchanged)"
    elif exc.errno in (errno.EACCES, errno.EPERM, errno.EROFS):
        hint = "; check the permissions of the folder"
    err = FileWriteError(f"cannot write the {what} {path}: {reason}{hint}", path=path)
    err.errno, err.strerror, err.filename = exc.errno, exc.strerror, path
    return err


def refuse_link(path: str, what: str) -> None:
    """The one output-path policy of every writer (:func:`atomic_write`,
    :func:`atomic_directory`, the command line's ``--out``): an output path that
    is a symbolic link is refused with :class:`~subid.errors.FileWriteError`
    naming where it points. subid never writes through a link, to a file or
    a folder alike, so an output can never land outside the place named."""
    if os.path.islink(path):
        raise FileWriteError(f"cannot write the {what} {path}: it is a symbolic link (to "
                             f"{os.readlink(path)}); subid does not write through links: "
                             "give the path of the target itself, or another name",
                             path=path)


@contextlib.contextmanager
def made_folders(path):
    """Create the folder ``path`` (and missing parents) for the writes of the
    ``with`` block; when the block fails, the folders this call created are
    removed again if they are still empty: a failed write (a full disk, a
    refused file) leaves nothing behind, not even an empty folder."""
    path = os.path.abspath(os.fspath(path))
    created, probe = [], path
    while probe and not os.path.lexists(probe):
        created.append(probe)
        parent = os.path.dirname(probe)
        if parent == probe:
            break
        probe = parent
    try:
        os.makedirs(path, exist_ok=True)
    except OSError as exc:
        raise _write_error(exc, path, "folder") from None
    try:
        yield path
    except BaseException:
        for folder in created:                 # deepest first
            with contextlib.suppress(OSError):
                os.rmdir(folder)
        raise


@contextlib.contextmanager
def atomic_write(path, mode: str = "wb", encoding: str | None = None, *, what: str = "file"):
    """Yield a file handle whose content replaces ``path`` only when complete.

    The data go to a new temporary file in the same directory, which is
    flushed, synced to disk and renamed over ``path``: a reader, or a crash
    mid-write, never sees a partly written file, and an existing file is left
    untouched when writing fails. Operating-system errors (disk full,
    permissions) become :class:`~subid.errors.FileWriteError` naming
    ``path``, never the temporary file. Temporary files left by killed
    writers of the same ``path`` are removed.
    """
    path = os.fspath(path)
    if "\x00" in path:
        raise FileWriteError(f"the file name {path!r} holds a NUL byte",
                             path=path.replace("\x00", "\\0"))
    refuse_link(path, what)
    try:
        existing = os.stat(path).st_mode
    except FileNotFoundError:
        existing = None
    except OSError as exc:
        raise _write_error(exc, path, what) from None
    if existing is not None and not stat.S_ISREG(existing):
        kind = next((k for test, k in _KINDS if test(existing)), "not a regular file")
        raise FileWriteError(f"cannot write the {what} {path}: it is {kind}, and subid "
                             "replaces regular files only", path=path)
    remove_stale_temporaries(path)
    directory = os.path.dirname(os.path.abspath(path))
    tmp = _temp_name(path)
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
    except OSError as exc:
        raise _write_error(exc, path, what) from None
    try:
        with os.fdopen(fd, mode, encoding=encoding) as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if isinstance(exc, OSError) and not isinstance(exc, FileWriteError):
            raise _write_error(exc, path, what) from None
        raise
    _fsync_directory(directory)


def write_bytes(path, data, *, what: str = "file") -> None:
    """Write ``data`` (bytes or str) to ``path`` atomically (:func:`atomic_write`)."""
    if isinstance(data, str):
        with atomic_write(path, "w", encoding="utf-8", what=what) as fh:
            fh.write(data)
    else:
        with atomic_write(path, "wb", what=what) as fh:
            fh.write(data)


def write_json(path, obj, *, what: str = "file", **options) -> None:
    """``json.dump(obj)`` to ``path`` atomically (UTF-8); ``options`` go to json.dump."""
    import json
    with atomic_write(path, "w", encoding="utf-8", what=what) as fh:
        json.dump(obj, fh, **options)


def save_figure(fig, path, *, what: str = "figure", **options) -> None:
    """``fig.savefig`` to ``path`` atomically; the format is the file's extension
    (PNG without one), ``options`` go to savefig (``dpi=...``)."""
    ext = os.path.splitext(os.fspath(path))[1].lower().lstrip(".")
    with atomic_write(path, "wb", what=what) as fh:
        fig.savefig(fh, format=ext or "png", **options)


# -- whole folders ---------------------------------------------------------------
def _exchange(a: str, b: str) -> bool:
    """Swap two paths atomically (Linux renameat2 RENAME_EXCHANGE); False if unsupported."""
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or None, use_errno=True)
        renameat2 = libc.renameat2
    except (OSError, AttributeError):
        return False
    renameat2.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p,
                          ctypes.c_uint]
    at_fdcwd, rename_exchange = -100, 2
    if renameat2(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), rename_exchange) == 0:
        return True
    code = ctypes.get_errno()
    if code in (errno.ENOSYS, errno.EINVAL, errno.ENOTSUP):
        return False
    raise OSError(code, os.strerror(code), b)


@contextlib.contextmanager
def atomic_directory(path, *, owned=None, what: str = "output folder"):
    """Yield a new staging folder that replaces the folder ``path`` when complete.

    Every output of a command is written into the staging folder (next to
    ``path``); on success it takes the place of ``path`` in one atomic
    exchange (Linux ``renameat2``; elsewhere two renames), so ``path`` holds
    either the previous run's complete outputs or the new run's, never a
    mix. On failure or interruption the staging folder is removed and
    ``path`` is unchanged. Staging folders of killed runs are removed on the
    next run.

    ``owned`` is a predicate telling whether an existing ``path`` may be
    replaced (e.g. it is empty or holds only a previous run's outputs);
    when it says no, :class:`~subid.errors.FileWriteError` is raised before
    anything is written.
    """
    path = os.path.abspath(os.fspath(path))
    if "\x00" in path:
        raise FileWriteError(f"the folder name {path!r} holds a NUL byte",
                             path=path.replace("\x00", "\\0"))
    refuse_link(path, what)
    if os.path.exists(path):
        if not os.path.isdir(path):
            raise FileWriteError(f"{path} exists and is not a folder; choose another "
                                 f"{what}", path=path)
        if owned is not None and not owned(path):
            raise FileWriteError(f"{path} holds files that subid did not write; choose a new "
                                 f"or empty {what} (nothing was written)", path=path)
    parent = os.path.dirname(path)
    try:
        os.makedirs(parent, exist_ok=True)
    except OSError as exc:
        raise _write_error(exc, parent, "folder") from None
    remove_stale_temporaries(path)
    staging = _temp_name(path, "staging")
    try:
        os.mkdir(staging)
    except OSError as exc:
        raise _write_error(exc, path, what) from None
    try:
        yield staging
        _fsync_directory(staging)
        if not os.path.exists(path):
            os.rename(staging, path)
        elif _exchange(staging, path):
            shutil.rmtree(staging, ignore_errors=True)   # now the previous run's folder
        else:
            old = _temp_name(path, "old")
            os.rename(path, old)
            os.rename(staging, path)
            shutil.rmtree(old, ignore_errors=True)
    except BaseException as exc:
        shutil.rmtree(staging, ignore_errors=True)
        if isinstance(exc, FileWriteError) and staging in str(exc):
            # name the file the user asked for, never the hidden staging folder
            err = FileWriteError(str(exc).replace(staging, path) + " (the folder is "
                                 "unchanged)", path=(exc.path or "").replace(staging, path))
            err.errno, err.strerror = exc.errno, exc.strerror
            raise err from None
        if isinstance(exc, OSError) and not isinstance(exc, FileWriteError):
            raise _write_error(exc, path, what) from None
        raise
    _fsync_directory(parent)
