"""Data paths given as fsspec URLs (``s3://``, ``gs://``, ``https://``, ``file://``, ...).

The loaders read local files, so a URL is first copied, file by file, into a
temporary folder that keeps the URL's last path component as its name (loaders
name drives after their folders); an error in a copy names the URL. Only the process that
runs ``bench run`` reads the URL; workers (processes or Ray) receive the loaded drives.
"""

from __future__ import annotations

import re
import shutil
import tempfile
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path, PurePosixPath

from posbench.scenarios.errors import DataError

# "scheme:/..." - pathlib turns "s3://bucket/key" into "s3:/bucket/key"; one-letter schemes
# are Windows drives, not URLs
_URL = re.compile(r"^([A-Za-z][A-Za-z0-9+.\-]+):/+(.*)$")


_ROOTED = ("file", "local")  # schemes whose path is absolute: file:///tmp/x


def as_url(path: str | Path) -> str | None:
    """The fsspec URL that ``path`` stands for, or None for a local path. A URL that went
    through :class:`pathlib.Path` (``s3:/bucket/key``) gets its ``//`` back."""
    s = str(path)
    m = _URL.match(s)
    if m is None or Path(s).exists():
        return None
    scheme, rest = m.groups()
    return f"{scheme}://{'/' if scheme.lower() in _ROOTED else ''}{rest}"


def local_path(path: str | Path) -> Path | None:
    """The local file or folder ``path`` names: itself, or the path of a ``file://`` URL;
    None for a URL of another file system (copied first, :func:`fetch`)."""
    url = as_url(path)
    if url is None:
        return Path(path)
    scheme, _, rest = url.partition("://")
    return Path(rest) if scheme.lower() in _ROOTED else None


def fetch(url: str, dest: Path) -> Path:
    """Copy the file or folder at ``url`` to ``dest / <its name>`` and return that path.

    Raises DataError (naming the URL) if fsspec or the protocol's backend is missing,
    or the URL does not exist or cannot be read."""
    try:
        import fsspec
    except ImportError:
        raise DataError(
            url,
            "URL data paths need fsspec (pip install fsspec, plus s3fs / gcsfs "
            "for s3:// / gs://); without it give a local path",
        ) from None
    try:
        fs, root = fsspec.core.url_to_fs(url)
    except (ImportError, ValueError) as e:  # unknown protocol or its backend not installed
        raise DataError(url, f"cannot open this URL: {e}") from None
    root = root.rstrip("/") or root
    try:
        if not fs.exists(root):
            raise DataError(url, "no such file or folder")
        name = PurePosixPath(root).name or "data"
        local = dest / name
        if fs.isdir(root):
            files = sorted(fs.find(root, withdirs=False))
            if not files:
                raise DataError(url, "folder is empty")
            for f in files:
                target = local / PurePosixPath(f).relative_to(PurePosixPath(root))
                target.parent.mkdir(parents=True, exist_ok=True)
                fs.get_file(f, str(target))
        else:
            local.parent.mkdir(parents=True, exist_ok=True)
            fs.get_file(root, str(local))
    except OSError as e:
        raise DataError(url, f"cannot read: {e}") from None
    return local


@contextmanager
def local_paths(paths: Sequence[str | Path] | None) -> Iterator[list[Path] | None]:
    """``paths`` with every URL replaced by a local copy, in the same order; the copies
    are removed on exit, and a :class:`DataError` raised meanwhile about a copied file names
    it by its URL. ``None`` (no data given) passes through."""
    if not paths:
        yield None if paths is None else []
        return
    urls = [as_url(p) for p in paths]
    if not any(urls):
        yield [Path(p) for p in paths]
        return
    tmp = Path(tempfile.mkdtemp(prefix="posbench-fetch-"))
    try:
        out, copies = [], {}
        for i, (p, u) in enumerate(zip(paths, urls, strict=True)):
            out.append(Path(p) if u is None else fetch(u, tmp / str(i)))
            if u is not None:
                copies[str(out[-1])] = u
        try:
            yield out
        except DataError as e:
            raise _named_by_url(e, copies) from None
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _named_by_url(error: DataError, copies: dict[str, str]) -> DataError:
    """``error`` naming the URL a file was copied from instead of the copy (``copies``: local
    copy -> URL); as it is where it names no copy."""
    where = error.path or ""
    for copy, url in copies.items():
        if where == copy or where.startswith(copy + "/"):
            return DataError(url + where[len(copy) :], error.detail)
    return error
