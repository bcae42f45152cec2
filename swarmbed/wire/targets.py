"""Loading code named by a target: ``package.module:Class`` or ``path/to/file.py:Class``.

The launcher resolves the names in an experiment (``allocator.name``, ``scenario.kind``) to
targets; processes load exactly the targets they are handed, and never look a name up.

A file is loaded as module ``swarmbed_user_plugin_<stem>_<digest>``, the digest taken from the
file's bytes: two different files of one name (``a/plugin.py``, ``b/plugin.py``) in one process, a
sweep worker's, stay two modules, while the same file copied to another host gets the same module
name there, which is what a snapshot's ``module:qualname`` type names rely on.
"""

from __future__ import annotations

import hashlib
import importlib
import importlib.util
import sys
import traceback
from pathlib import Path
from types import ModuleType
from typing import TypeVar

T = TypeVar("T")


class TargetError(ValueError):
    """A target that cannot be imported or is not what it should be."""


def is_target(text: str) -> bool:
    return ":" in text


def file_digest(path: Path) -> str:
    """The sha256 of a plugin file's bytes, in hex."""
    return hashlib.sha256(path.read_bytes()).hexdigest()


def user_module_name(path: Path, digest: str | None = None) -> str:
    """The module name a plugin file loads as: its stem and a digest of its bytes."""
    digest = (digest or file_digest(path))[:12]
    stem = "".join(c if c.isalnum() else "_" for c in path.stem)
    return f"swarmbed_user_plugin_{stem}_{digest}"


def file_digests(*targets: str) -> dict[str, str]:
    """``{file: sha256}`` of the ``path/file.py`` modules among ``targets`` (what the launcher
    checked, handed on with them); a file that is not there is left to :func:`load_target` to name."""
    out = {}
    for target in targets:
        ref = target.rpartition(":")[0]
        if ref.endswith(".py") and Path(ref).is_file():
            out[ref] = file_digest(Path(ref))
    return out


def _import_module(ref: str, digest: str | None = None) -> ModuleType:
    if ref.endswith(".py"):
        path = Path(ref).resolve()
        if not path.is_file():
            raise TargetError(f"file {ref} does not exist")
        found = file_digest(path)
        if digest is not None and found != digest:
            raise TargetError(
                f"file {ref} here is not the file the launcher checked (sha256 {found[:12]}... here, "
                f"{digest[:12]}... there): copy the same file to this machine"
            )
        mod_name = user_module_name(path, found)
        if mod_name in sys.modules:
            return sys.modules[mod_name]
        spec = importlib.util.spec_from_file_location(mod_name, path)
        if spec is None or spec.loader is None:
            raise TargetError(f"cannot load {ref} as a Python module")
        module = importlib.util.module_from_spec(spec)
        sys.modules[mod_name] = module
        try:
            spec.loader.exec_module(module)
        except BaseException:
            del sys.modules[mod_name]
            raise
        return module
    return importlib.import_module(ref)


def load_target(target: str, base: type[T], digests: dict[str, str] | None = None) -> type[T]:
    """The class ``target`` names; it must be a subclass of ``base``. ``digests``: ``{file: sha256}``
    (:func:`file_digests`); a file target whose bytes differ is refused."""
    if not is_target(target):
        raise TargetError(f"{target!r} is not a target: expected 'module:Class' or 'path/to/file.py:Class'")
    module_ref, _, cls_name = target.rpartition(":")
    try:
        module = _import_module(module_ref, (digests or {}).get(module_ref))
    except TargetError as exc:  # ours: a file that is not there, not a module's own failure
        raise TargetError(f"cannot import {module_ref!r}: {exc}") from None
    except ImportError as exc:
        raise TargetError(f"cannot import {module_ref!r}: {exc}") from exc
    except SyntaxError as exc:  # the user's file: one line naming where, not a traceback through ours
        raise TargetError(
            f"cannot import {module_ref!r}: {type(exc).__name__}: {exc.msg} ({exc.filename}, line {exc.lineno})"
        ) from None
    except Exception as exc:  # the module raised as it was imported: where, in the user's code
        frame = traceback.extract_tb(exc.__traceback__)[-1]
        raise TargetError(
            f"cannot import {module_ref!r}: it raised {type(exc).__name__}: {exc} "
            f"({frame.filename}, line {frame.lineno})"
        ) from None
    if not hasattr(module, cls_name):
        raise TargetError(f"{module_ref} has no class {cls_name!r}")
    cls = getattr(module, cls_name)
    if not (isinstance(cls, type) and issubclass(cls, base)):
        raise TargetError(f"{target} is not a subclass of {base.__name__}")
    return cls
