"""Where numba keeps gpsdr's compiled kernels: a folder keyed by the kernels' sources.

numba's on-disk cache checks only the file that defines a ``@njit(cache=True)``
function (its modification time and size).  A kernel that calls a function or reads
a constant from another module -- ``filters/kernels_aekf.py`` calling
``models/cs_model.py`` -- is loaded stale from the cache after an edit of that
other module.  So the cache lives in a folder named by a hash of every
kernel-related source (:func:`kernel_sources`): any edit there selects a new, empty
folder and every kernel compiles afresh, while unchanged sources (another checkout
of the same commit, an installed copy) share one.

:func:`configure` runs when the package is imported (``gpsdr_cli/__init__.py``),
before any kernel module is: it sets ``NUMBA_CACHE_DIR``, which numba reads when a
cached function is decorated, to ``<root>/gpsdr-<key>``.  ``<root>`` is the
``NUMBA_CACHE_DIR`` the environment gave (a benchmark's empty folder stays empty),
else ``$XDG_CACHE_HOME/gpsdr/numba`` (``~/.cache/gpsdr/numba``).  Child processes
inherit the variable; a marker variable stops them nesting a second key.  When the
root cannot be created (a read-only home) nothing is set and numba falls back to
its own ``__pycache__`` rule.  ``GPSDR_KERNEL_CACHE_KEY=0`` disables the keying.

Only the standard library here: the package import must stay fast (hashing the
sources takes about a millisecond).
"""

from __future__ import annotations

import hashlib
import os
import shutil
import sys
from pathlib import Path

PACKAGE_DIR = Path(__file__).resolve().parent

#: Folders (relative to the package) whose every ``.py`` file is kernel-related.
KERNEL_DIRS: tuple[str, ...] = ("filters", "models")
#: Single modules that are kernel-related although they do not import numba.
KERNEL_FILES: tuple[str, ...] = ("conventions.py",)

#: The environment variable this module sets, and its marker for child processes.
ENV_CACHE_DIR = "NUMBA_CACHE_DIR"
ENV_MARKER = "GPSDR_KEYED_NUMBA_CACHE_DIR"
ENV_DISABLE = "GPSDR_KERNEL_CACHE_KEY"

#: How many keyed folders to keep under one root; older ones are removed.
KEEP_FOLDERS = 8
PREFIX = "gpsdr-"


def kernel_sources(package_dir: Path = PACKAGE_DIR) -> list[Path]:
    """Every source a compiled kernel may depend on, sorted.

    All ``.py`` files under :data:`KERNEL_DIRS`, the :data:`KERNEL_FILES`, and every
    other module of the package that imports numba (``align.py``, ``simulate.py``,
    readers with compiled loops).  Over-inclusion costs a recompile, never a wrong result.
    """
    found: set[Path] = set()
    for rel in KERNEL_DIRS:
        found.update((package_dir / rel).rglob("*.py"))
    for rel in KERNEL_FILES:
        path = package_dir / rel
        if path.is_file():
            found.add(path)
    for path in package_dir.rglob("*.py"):
        if path in found or path.name == "kernel_cache.py" or "__pycache__" in path.parts:
            continue
        try:
            text = path.read_bytes()
        except OSError:
            continue
        if b"from numba" in text or b"import numba" in text:
            found.add(path)
    return sorted(found)


def source_key(package_dir: Path = PACKAGE_DIR) -> str:
    """16 hex digits of a SHA-256 over the kernel sources' relative paths and contents,
    and the Python version (numba's cache files are per interpreter anyway)."""
    digest = hashlib.sha256(f"py{sys.version_info[0]}.{sys.version_info[1]}".encode())
    for path in kernel_sources(package_dir):
        digest.update(path.relative_to(package_dir).as_posix().encode())
        digest.update(b"\0")
        try:
            digest.update(path.read_bytes())
        except OSError:
            digest.update(b"<unreadable>")
        digest.update(b"\0")
    return digest.hexdigest()[:16]


def default_root() -> Path:
    """The user's cache folder for gpsdr's kernels (XDG base directory rule)."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "gpsdr" / "numba"


def _prune(root: Path, keep: Path) -> None:
    """Remove all but the :data:`KEEP_FOLDERS` most recently used keyed folders."""
    try:
        folders = [p for p in root.iterdir()
                   if p.is_dir() and p.name.startswith(PREFIX) and p != keep]
        folders.sort(key=lambda p: p.stat().st_mtime, reverse=True)
    except OSError:
        return
    for old in folders[KEEP_FOLDERS - 1:]:
        shutil.rmtree(old, ignore_errors=True)


def configure(environ: os._Environ[str] | dict[str, str] | None = None,
              package_dir: Path = PACKAGE_DIR) -> Path | None:
    """Point numba's cache at the folder for the current kernel sources; return it.

    None (and the environment untouched) when disabled or when no folder can be made.
    """
    env = os.environ if environ is None else environ
    if env.get(ENV_DISABLE, "1") == "0":
        return None
    given = env.get(ENV_CACHE_DIR, "")
    if given and given == env.get(ENV_MARKER):  # set by this module in a parent process
        root = Path(given).parent
    elif given:
        root = Path(given)
    else:
        root = default_root()
    target = root / f"{PREFIX}{source_key(package_dir)}"
    if not target.is_dir():
        try:
            target.mkdir(parents=True, exist_ok=True)
        except OSError:
            return None
        _prune(root, target)
    env[ENV_CACHE_DIR] = str(target)
    env[ENV_MARKER] = str(target)
    config = sys.modules.get("numba.core.config")
    if config is not None and environ is None:  # numba already imported: re-read its env
        config.reload_config()
    return target
