"""Where the configs and experiment scripts that ship with jflex are, in a source checkout and
once installed; and the folders jflex writes into (made on demand, or refused by name).

A checkout keeps them at its top (``configs/``, ``experiments/``, beside ``jflex/``); a wheel
carries the same folders inside the package (``jflex/configs``, ``jflex/experiments``, see
``[tool.setuptools]`` in pyproject.toml), so a script's ``parent.parent / "configs"`` holds in both.
"""

from __future__ import annotations

import pathlib

from ._errors import ConfigError

_PACKAGE = pathlib.Path(__file__).resolve().parent


def shipped_dirs(kind: str) -> list[pathlib.Path]:
    """The existing shipped folders named ``kind`` (``"configs"`` or ``"experiments"``): the
    installed package's copy, then the source checkout's (a folder above ``jflex/`` counts only
    when a ``pyproject.toml`` beside it says it is this project's checkout, not some
    ``site-packages/configs``)."""
    found = []
    if (_PACKAGE / kind).is_dir():
        found.append(_PACKAGE / kind)
    root = _PACKAGE.parent
    if (root / "pyproject.toml").is_file() and (root / kind).is_dir():
        found.append(root / kind)
    return found


def output_folder(path, field: str) -> pathlib.Path:
    """``path`` as an existing folder (created with its parents if missing), or a
    :class:`ConfigError` naming ``field`` when it is a file or cannot be created."""
    folder = pathlib.Path(path).expanduser()
    if folder.exists() and not folder.is_dir():
        raise ConfigError(f"{field} {str(folder)!r} is a file, not a folder: pass a folder (it is created if missing)")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigError(f"{field} {str(folder)!r} cannot be created as a folder ({type(exc).__name__}: {exc})") from None
    return folder
