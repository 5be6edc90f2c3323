"""Every public function, class and method of every public module has a docstring.

Public: a module whose dotted name has no component starting with ``_`` and a name
defined in that module (not imported into it) that does not start with ``_`` --
whether or not it is listed in ``__all__``. Methods are checked on public classes;
dunders, inherited methods and dataclass-generated methods are not (a method's
docstring is also accepted when it overrides a documented method of a base class, as
numpydoc and Sphinx do). ``nn`` is imported only when torch is installed.
"""

from __future__ import annotations

import importlib
import importlib.util
import inspect
import pkgutil
from typing import Any

import pytest

import robopercept


def _public_modules() -> list[str]:
    names = [robopercept.__name__]
    for info in pkgutil.walk_packages(robopercept.__path__, robopercept.__name__ + "."):
        parts = info.name.split(".")
        if any(p.startswith("_") for p in parts[1:]):
            continue
        if parts[1] == "nn" and importlib.util.find_spec("torch") is None:
            continue
        names.append(info.name)
    return names


def _inherited_doc(cls: type, name: str) -> bool:
    return any(
        getattr(getattr(base, name, None), "__doc__", None)
        for base in cls.__mro__[1:]
        if base is not object
    )


def undocumented(module: Any) -> list[str]:
    """Public functions, classes and methods defined in ``module`` with no docstring."""
    missing = []
    for name, obj in vars(module).items():
        if name.startswith("_") or getattr(obj, "__module__", None) != module.__name__:
            continue
        if inspect.isfunction(obj):
            if not inspect.getdoc(obj):
                missing.append(name)
        elif inspect.isclass(obj):
            if not (obj.__doc__ or "").strip():
                missing.append(name)
            for attr, member in vars(obj).items():
                if attr.startswith("_"):
                    continue
                func = member.fget if isinstance(member, property) else member
                func = getattr(func, "__func__", func)  # classmethod, staticmethod
                if not inspect.isfunction(func) or func.__qualname__ != f"{obj.__name__}.{attr}":
                    continue  # not a method written in this class body
                if not (func.__doc__ or "").strip() and not _inherited_doc(obj, attr):
                    missing.append(f"{name}.{attr}")
    return missing


MODULES = _public_modules()


@pytest.mark.parametrize("name", MODULES)
def test_public_names_have_docstrings(name: str) -> None:
    module = importlib.import_module(name)
    assert (module.__doc__ or "").strip(), f"module {name} has no docstring"
    missing = undocumented(module)
    assert not missing, f"{name}: no docstring on {missing}"


def test_checker_finds_a_missing_docstring() -> None:
    import types

    mod = types.ModuleType("fake")
    exec(
        "def f():\n    pass\n"
        "def g():\n    '''Doc.'''\n"
        "def _h():\n    pass\n"
        "class A:\n    '''Doc.'''\n"
        "    def m(self):\n        pass\n"
        "    @property\n    def p(self):\n        return 1\n"
        "    def _q(self):\n        pass\n"
        "class B(A):\n"
        "    def m(self):\n        pass\n",
        mod.__dict__,
    )
    for obj in vars(mod).values():
        if callable(obj):
            obj.__module__ = "fake"
    assert undocumented(mod) == ["f", "A.m", "A.p", "B", "B.m"]  # B.m overrides an undocumented A.m
