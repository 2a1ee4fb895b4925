"""The module paths of the flat layout (``accd_gym.vector``, ``accd_gym.evaluation``, ...) as
deprecated aliases of the modules' homes in the subpackages.

:data:`MOVED` maps every old path to its new one. A meta path finder (:class:`AliasFinder`,
registered by ``accd_gym/__init__.py``) answers imports of an old path with the module of the
new one, the same object (``accd_gym.vector is accd_gym.envs.vector``), so everything saved under
an old path still loads: pickles of env classes, policies and configurations, stable-baselines3
models and VecNormalize statistics, gymnasium entry points. An import statement (``import``,
``from ... import``), :func:`importlib.import_module` or attribute access on :mod:`accd_gym`
warns with a :class:`DeprecationWarning` naming the new path, once per old path and process
(afterwards the old path is in :data:`sys.modules`); an unpickler resolving a class by its old
module does not warn, so old pickles load quietly, also under ``-W error``.
"""

from __future__ import annotations

import dis
import importlib
import importlib.abc
import importlib.machinery
import os
import sys
import types
import warnings
from typing import Optional, Sequence

#: Old module path -> the module's home.
MOVED: dict[str, str] = {
    "accd_gym.config": "accd_gym.envs.config",
    "accd_gym.core_env": "accd_gym.envs.core_env",
    "accd_gym.env": "accd_gym.envs.env",
    "accd_gym.render": "accd_gym.envs.render",
    "accd_gym.sb3": "accd_gym.envs.sb3",
    "accd_gym.task": "accd_gym.envs.task",
    "accd_gym.tiers": "accd_gym.envs.tiers",
    "accd_gym.vector": "accd_gym.envs.vector",
    "accd_gym.baselines": "accd_gym.control.baselines",
    "accd_gym.lqr": "accd_gym.control.lqr",
    "accd_gym.training": "accd_gym.learning.training",
    "accd_gym.rllib": "accd_gym.learning.rllib",
    "accd_gym.benchmark": "accd_gym.evals.benchmark",
    "accd_gym.distributed": "accd_gym.evals.distributed",
    "accd_gym.evaluation": "accd_gym.evals.evaluation",
    "accd_gym.sweep": "accd_gym.evals.sweep",
    "accd_gym.fidelity": "accd_gym.studies.fidelity",
    "accd_gym.settle": "accd_gym.studies.settle",
    "accd_gym.study": "accd_gym.studies.study",
    "accd_gym.browser": "accd_gym.replays.browser",
    "accd_gym.recording": "accd_gym.replays.recording",
    "accd_gym.replay": "accd_gym.replays.replay",
}

_IMPORT_NAME = dis.opmap["IMPORT_NAME"]
#: Files whose frames are import machinery, not the code that asked for the module.
_MACHINERY = (
    os.path.normcase(os.path.abspath(__file__)),
    os.path.normcase(os.path.abspath(os.path.join(os.path.dirname(__file__), "__init__.py"))),
    os.path.normcase(os.path.abspath(importlib.__file__ or "")),
)


def _importer() -> tuple[int, bool]:
    """The stack level of the code importing an old path (for :func:`warnings.warn` called in
    this module's caller) and whether that code is an import statement or went through
    :func:`importlib.import_module` (an unpickler calls ``__import__`` from C or from
    ``pickle.find_class``: neither)."""
    frame = sys._getframe(2)
    level = 2
    via_importlib = False
    while frame is not None:
        name = frame.f_code.co_filename
        if "importlib" in name and "_bootstrap" in name:
            frame = frame.f_back  # type: ignore[assignment]
            continue  # warnings does not count these frames either
        if os.path.normcase(os.path.abspath(name)) not in _MACHINERY:
            break
        via_importlib = via_importlib or name.endswith(os.path.join("importlib", "__init__.py"))
        frame = frame.f_back  # type: ignore[assignment]
        level += 1
    if frame is None:
        return level, False
    code = frame.f_code.co_code
    statement = 0 <= frame.f_lasti < len(code) and code[frame.f_lasti] == _IMPORT_NAME
    return level, statement or via_importlib


class _AliasLoader(importlib.abc.Loader):
    """Loads an old path: imports its home and puts that module under the old name."""

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> Optional[types.ModuleType]:
        """The default (a placeholder module that :meth:`exec_module` replaces)."""
        return None

    def exec_module(self, module: types.ModuleType) -> None:
        """Replaces the placeholder in :data:`sys.modules` by the home module (importlib
        returns what :data:`sys.modules` holds after this call), warning an importing statement."""
        old = module.__name__
        new = MOVED[old]
        level, warn = _importer()
        home = importlib.import_module(new)
        sys.modules[old] = home
        if warn:
            warnings.warn(f"{old} is deprecated: import {new}", DeprecationWarning, stacklevel=level)


class AliasFinder(importlib.abc.MetaPathFinder):
    """Finds the old module paths of :data:`MOVED` (and nothing else)."""

    def find_spec(
        self, fullname: str, path: Optional[Sequence[str]], target: Optional[types.ModuleType] = None
    ) -> Optional[importlib.machinery.ModuleSpec]:
        """A spec for an old path, None for any other module."""
        if fullname not in MOVED:
            return None
        return importlib.machinery.ModuleSpec(fullname, _AliasLoader())


def register() -> None:
    """Puts one :class:`AliasFinder` first on :data:`sys.meta_path` (again after a reload)."""
    sys.meta_path[:] = [f for f in sys.meta_path if type(f).__name__ != "AliasFinder" or
                        type(f).__module__ != __name__]
    sys.meta_path.insert(0, AliasFinder())


def old_module(name: str) -> Optional[types.ModuleType]:
    """The module of ``accd_gym.<name>`` when that is an old path (warning as an import does), else None."""
    full = f"accd_gym.{name}"
    if full not in MOVED:
        return None
    return importlib.import_module(full)
