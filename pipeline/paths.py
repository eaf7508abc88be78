"""Where data lives: the bundled data folder and the external data root.

Config inputs are path templates. ``{bundled}`` is the project's ``data/``
folder (permissively licensed meshes and images, shipped in the repository and
installed with the package as ``topomatch.data``; :func:`data_path` names one of
its files from any folder, and the command line's ``bundled:NAME``);
``{data_root}`` is the external data root, set with ``--data-root`` or the
``TOPOMATCH_DATA_ROOT`` environment variable (CI points it at ``../shared/data``).
Relative paths are relative to the config file's folder. Glob patterns
(``*``, ``?``, ``[...]``) are expanded and sorted.
"""

from __future__ import annotations

import difflib
import glob
import os
import re
from pathlib import Path

from topomatch.pipeline.errors import ConfigError, InputError

DATA_ROOT_ENV = "TOPOMATCH_DATA_ROOT"

#: The repository's bundled data folder (``topomatch/data`` in an installed package).
BUNDLED_DIR = Path(__file__).resolve().parents[1] / "data"

#: How the command line names a file of the bundled data: ``bundled:torus.off``, ``bundled:meshes/torus.off``.
BUNDLED_PREFIX = "bundled:"


def data_root(explicit: str | Path | None = None) -> Path | None:
    """The external data root: ``explicit``, else ``$TOPOMATCH_DATA_ROOT``, else None."""
    value = explicit if explicit is not None else os.environ.get(DATA_ROOT_ENV)
    if not value:
        return None
    return Path(value).expanduser().resolve()


def bundled_files() -> list[str]:
    """Every file of the bundled data, as its path under the data folder (``meshes/torus.off``), sorted."""
    base = BUNDLED_DIR.resolve()
    return sorted(p.relative_to(base).as_posix() for p in base.rglob("*") if p.is_file()
                  and not any(part.startswith((".", "__")) for part in p.relative_to(base).parts))


def data_path(name: str | Path = "") -> Path:
    """A file or folder of the bundled data (``topomatch.data``, the repository's ``data/``), from any folder.

    ``name`` is its path under the data folder (``"meshes/torus.off"``, ``"images/itk/BrainT1Slice.png"``,
    ``"meshes"``) or the end of one found once there (``"torus.off"``, ``"itk/BrainT1Slice.png"``); ``""`` is
    the folder itself. The command line's spelling, ``"bundled:torus.off"``, is accepted too.

    Raises
    ------
    InputError
        ``name`` lies outside the data folder (``../pyproject.toml``, an absolute path), is not bundled (the
        message lists the bundled files closest to it) or names several files (the message lists them).
    """
    text = str(name).removeprefix(BUNDLED_PREFIX)
    shown = f"{BUNDLED_PREFIX}{text}"
    base = BUNDLED_DIR.resolve()
    path = (base / text).resolve()
    if not path.is_relative_to(base):
        raise InputError(shown, f"outside the bundled data folder {base}: refused (name a file under it, "
                                f"e.g. meshes/torus.off)")
    if path.exists():
        return path
    files = bundled_files()
    same_name = [f for f in files if f.endswith(f"/{text}")]
    if len(same_name) == 1:
        return base / same_name[0]
    if same_name:
        raise InputError(shown, f"several bundled files end so: {', '.join(same_name)}; name one by its folder")
    by_name = {f.rpartition("/")[2]: f for f in files}
    close = difflib.get_close_matches(text, files, n=5, cutoff=0.5)
    close += [by_name[n] for n in difflib.get_close_matches(text, list(by_name), n=5, cutoff=0.5)]
    suffix = "".join(Path(text).suffixes[-2:]).lower()
    close = list(dict.fromkeys(close)) or [f for f in files if suffix and f.lower().endswith(suffix)][:8]
    hint = (f"closest: {', '.join(close[:8])}" if close else
            f"it holds {len(files)} files under {', '.join(sorted({f.rpartition('/')[0] or '.' for f in files}))}")
    raise InputError(shown, f"not among the bundled data ({base}); {hint}")


def uses_data_root(template: str) -> bool:
    return "{data_root}" in template


def resolve_input(template: str, *, base_dir: Path, root: Path | None, where: str) -> list[Path]:
    """Expand one input template into existing files.

    Raises
    ------
    ConfigError
        ``{data_root}`` is used but no data root is set, or the template is malformed.
    InputError
        No file matches (names the resolved path).
    """
    if uses_data_root(template) and root is None:
        raise ConfigError(
            f"{where}: {template!r} needs the external data root; pass --data-root DIR "
            f"or set {DATA_ROOT_ENV} (e.g. to ../shared/data)"
        )
    # exact tokens, not str.format: a format spec such as {bundled:>1000000000} would pad to gigabytes
    text = template.replace("{data_root}", str(root) if root else "").replace("{bundled}", str(BUNDLED_DIR))
    unknown = re.search(r"\{[^{}/]*\}", text)
    if unknown:
        raise ConfigError(f"{where}: bad path template {template[:200]!r}: unknown placeholder "
                          f"{unknown.group()[:60]!r}; only {{data_root}} and {{bundled}} are known")
    path = Path(text).expanduser()
    if not path.is_absolute():
        path = base_dir / path
    if glob.has_magic(str(path)):
        matches = sorted(Path(p) for p in glob.glob(str(path)) if Path(p).is_file())
        if not matches:
            raise InputError(path, "no file matches this pattern")
        return matches
    if not path.exists():
        raise InputError(path, "file not found")
    if not (path.is_file() or path.is_dir()):  # reading a FIFO blocks until something writes to it
        raise InputError(path, "not a regular file (a FIFO, socket or device): refused")
    return [path]


def display_path(path: str | Path, root: Path | None = None) -> str:
    """``path`` written with the ``{bundled}`` / ``{data_root}`` prefix when it lies under one."""
    path = Path(path).resolve()
    for prefix, base in (("{bundled}", BUNDLED_DIR), ("{data_root}", root)):
        if base is not None and path.is_relative_to(base):
            return f"{prefix}/{path.relative_to(base).as_posix()}"
    return str(path)
