"""A controller described in one file: ``controller.json``, written by every run, read back
by ``--controller FILE.json``.

The file names the controller (a registry name or ``module:Class``) and the options its
constructor was given, so that the same controller is built again, in ``cosim run``, in a
campaign's variant or in the Python API, without retyping a dozen ``--option``\\ s; and it
fingerprints the files those options name (the robust MPC's model, a problem file) with
their SHA-256, so that a model retrained since is noticed instead of silently controlling::

    {"format": "gru-mpc-controller/1",
     "controller": "robust-mpc",
     "options": {"model": "/abs/models/cstr_gru.json", "law": "tracking", "N": 80},
     "files": {"model": {"sha256": "9f2c…"}}}

A relative path in ``options`` is relative to the file's folder. The options are the ones
given (the controller fills in its defaults when it is built, and records the full set in
``summary.json``). :func:`load` checks everything in one place and names the file and the
key in a one-line error.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from cosim.core.errors import CosimError

__all__ = ["FILE_NAME", "FORMAT", "describe", "is_controller_file", "load", "write"]

#: The description's format tag (bumped when a key changes meaning).
FORMAT = "gru-mpc-controller/1"
#: The name of the description a run writes into its output folder.
FILE_NAME = "controller.json"
#: Options that name files (the robust MPC's model and problem, a controller FMU's path):
#: fingerprinted when they are paths to existing files.
FILE_OPTIONS = ("model", "problem", "path")
_KEYS = {"format", "controller", "options", "files"}


def is_controller_file(name: str) -> bool:
    """Whether a ``--controller`` value names a description file (``*.json``) rather than a
    registry name or ``module:Class``."""
    return name.lower().endswith(".json")


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def describe(controller: str, options: Mapping[str, Any]) -> dict[str, Any]:
    """The description of ``controller`` built with ``options``: JSON-ready, file options
    made absolute and fingerprinted. Options that are not JSON values (objects given in
    Python) are refused."""
    opts: dict[str, Any] = {}
    files: dict[str, dict[str, str]] = {}
    for key, value in options.items():
        if key in FILE_OPTIONS and isinstance(value, (str, Path)) and Path(value).is_file():
            path = Path(value).resolve()
            opts[key] = str(path)
            files[key] = {"sha256": _sha256(path)}
            continue
        try:
            json.dumps(value, allow_nan=False)
        except (TypeError, ValueError):
            raise CosimError(f"controller option {key!r}: {type(value).__name__} cannot be "
                             f"written to {FILE_NAME} (give a JSON value or a file path)"
                             ) from None
        opts[key] = value
    return {"format": FORMAT, "controller": controller, "options": opts, "files": files}


def write(path: str | Path, doc: Mapping[str, Any]) -> Path:
    """Write a description (:func:`describe`) atomically; its path. A failed write is a
    one-line :class:`~cosim.core.errors.OutputError` naming the file."""
    from cosim.core.atomicio import output_error, write_text

    try:
        write_text(path, json.dumps(doc, indent=1) + "\n")
    except OSError as exc:
        raise output_error(path, exc) from None
    return Path(path)


def load(path: str | Path) -> tuple[str, dict[str, Any]]:
    """``(controller, options)`` of a description file, checked: the format, the keys, the
    controller's name, file options resolved against the file's folder and their
    fingerprints compared.

    Raises
    ------
    CosimError
        One line naming the file (and the key): unreadable or not JSON, an unknown format
        or key, a missing or changed file.
    """
    path = Path(path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise CosimError(f"{path}: controller file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise CosimError(f"{path}: cannot read controller file: {exc}") from None
    except json.JSONDecodeError as exc:
        raise CosimError(f"{path}:{exc.lineno}:{exc.colno}: not JSON: {exc.msg}") from None
    if not isinstance(doc, dict):
        raise CosimError(f"{path}: a controller file is a JSON object")
    if doc.get("format") != FORMAT:
        raise CosimError(f"{path}: key 'format': expected {FORMAT!r}, got "
                         f"{doc.get('format')!r}")
    unknown = sorted(set(doc) - _KEYS)
    if unknown:
        raise CosimError(f"{path}: unknown key {unknown[0]!r} (known: {', '.join(sorted(_KEYS))})")
    name = doc.get("controller")
    if not isinstance(name, str) or not name or is_controller_file(name):
        raise CosimError(f"{path}: key 'controller': a registry name or module:Class, got "
                         f"{name!r}")
    options, files = doc.get("options", {}), doc.get("files", {})
    if not isinstance(options, dict) or not isinstance(files, dict):
        raise CosimError(f"{path}: keys 'options' and 'files' are JSON objects")
    options = dict(options)
    for key, value in options.items():
        if key in FILE_OPTIONS and isinstance(value, str) and (
                key in files or (path.parent / value).is_file()):
            options[key] = str((path.parent / value).resolve())
    for key, record in files.items():
        _check_file(path, key, options.get(key), record)
    return name, options


def _check_file(path: Path, key: str, value: Any, record: Any) -> None:
    """The file of option ``key`` exists and has the recorded SHA-256."""
    if not isinstance(value, str) or not isinstance(record, dict) or not isinstance(
            record.get("sha256"), str):
        raise CosimError(f"{path}: key 'files.{key}': expected {{\"sha256\": ...}} for "
                         f"option {key!r}")
    target = Path(value)
    if not target.is_file():
        raise CosimError(f"{path}: option {key!r}: {target} not found")
    if _sha256(target) != record["sha256"]:
        raise CosimError(f"{path}: option {key!r}: {target} changed since the controller was "
                         "recorded (SHA-256 differs); run it with its new options instead")
