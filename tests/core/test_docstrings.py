"""Every public function of the core says what each of its parameters is; the package maps name real things.

Like python-control's ``control/tests/docstrings_test.py``. The set checked:

* **public functions**: every function named in the ``__all__`` of a module of
  ``eha_core`` whose own name (and whose packages' names) do not start with ``_``
  (a function defined in a private module and re-exported through a public
  ``__all__`` is public, and is checked once);
* **public methods**: every function, static method and class method whose name
  does not start with ``_``, defined in the body of a public class (a class named
  in such an ``__all__``) or of one of its ``eha_core`` base classes. Properties,
  dunder methods (the constructor included) and what a class inherits from
  outside ``eha_core`` (``NamedTuple``, ``Exception``...) are not checked, nor is a
  dataclass field whose default happens to be a function.

The rule, for each function of that set:

1. it has a docstring;
2. each parameter of its signature other than ``self``/``cls`` is documented:

   * if the docstring has a numpydoc ``Parameters`` (or ``Other Parameters``)
     section, the parameter is an entry of it: a line at the section's indent
     ``name : type`` or ``name`` (several names may share one entry,
     ``t_end, dt : float``);
   * if it has no such section (a short docstring, the preferred form being the
     section), the parameter's name appears in the text in double backquotes,
     ``name``;

   ``*args`` and ``**kwargs`` may be documented as such (``*args``, ``**kwargs``)
   or not at all.

And the map of each package (the docstring of ``eha_core/__init__.py`` and of
``eha_core/identify/__init__.py``): every ``name -- description`` line of it
names a module or attribute that exists.
"""

from __future__ import annotations

import dataclasses
import importlib
import inspect
import pkgutil
import re
import types

import pytest

import eha_core

PACKAGE = "eha_core"
SECTION = re.compile(r"^(?P<title>[A-Z][A-Za-z ]*)\n-{3,}$", re.MULTILINE)
PARAMETER_SECTIONS = ("Parameters", "Other Parameters")


def public_modules() -> list[types.ModuleType]:
    """The modules of ``eha_core`` no part of whose dotted name starts with ``_``, the package first."""
    names = [PACKAGE] + [info.name for info in pkgutil.walk_packages(eha_core.__path__, PACKAGE + ".")]
    return [importlib.import_module(name) for name in names
            if not any(part.startswith("_") for part in name.split("."))]


def _own(obj) -> bool:
    return getattr(obj, "__module__", "").split(".")[0] == PACKAGE


def _methods(cls: type):
    """``(name, function)`` for the public methods defined in ``cls`` or its eha_core bases."""
    # a dataclass field whose default is a function (a rule's predicate) is a value, not a method
    seen = {f.name for f in dataclasses.fields(cls)} if dataclasses.is_dataclass(cls) else set()
    for klass in cls.__mro__:
        if not _own(klass):
            continue
        for name, attr in vars(klass).items():
            if name.startswith("_") or name in seen:
                continue
            seen.add(name)
            if isinstance(attr, (staticmethod, classmethod)):
                attr = attr.__func__
            if inspect.isfunction(attr):
                yield f"{cls.__qualname__}.{name}", attr


def public_functions() -> dict[str, types.FunctionType]:
    """Every public function and public method of public classes, keyed ``module.name``, each once."""
    found: dict[str, types.FunctionType] = {}
    ids = set()
    for module in public_modules():
        for name in getattr(module, "__all__", ()):
            obj = getattr(module, name)
            if not _own(obj):
                continue
            if inspect.isfunction(obj):
                candidates = [(name, obj)]
            elif inspect.isclass(obj):
                candidates = list(_methods(obj))
            else:
                continue
            for label, function in candidates:
                if id(function) not in ids:
                    ids.add(id(function))
                    found[f"{module.__name__}.{label}"] = function
    return found


def sections(doc: str) -> dict[str, str]:
    """The numpydoc sections of a (cleaned) docstring: title -> body."""
    heads = list(SECTION.finditer(doc))
    return {head["title"]: doc[head.end():heads[i + 1].start() if i + 1 < len(heads) else len(doc)]
            for i, head in enumerate(heads)}


def section_names(body: str) -> set[str]:
    """The names the entries of a Parameters section document (``a, b : float`` gives a and b)."""
    lines = [line for line in body.splitlines() if line.strip()]
    if not lines:
        return set()
    indent = min(len(line) - len(line.lstrip()) for line in lines)
    names = set()
    for line in lines:
        if len(line) - len(line.lstrip()) == indent:
            head = line.strip().split(" : ")[0].rstrip(":")
            names.update(part.strip() for part in head.split(","))
    return names


def undocumented(function) -> list[str]:
    """The parameters of ``function`` its docstring does not document, by the rule of this module."""
    doc = inspect.getdoc(function) or ""
    found = sections(doc)
    entries = set().union(*(section_names(found[title]) for title in PARAMETER_SECTIONS if title in found))
    has_section = any(title in found for title in PARAMETER_SECTIONS)
    missing = []
    for name, parameter in inspect.signature(function).parameters.items():
        if name in ("self", "cls"):
            continue
        if parameter.kind in (parameter.VAR_POSITIONAL, parameter.VAR_KEYWORD):
            continue  # may be documented as *args / **kwargs, or not at all
        if has_section:
            if name not in entries:
                missing.append(name)
        elif f"``{name}``" not in doc:
            missing.append(name)
    return missing


FUNCTIONS = public_functions()


def test_the_set_is_the_core():
    """A guard against a collector that finds nothing: the core has many public functions and methods."""
    assert len(FUNCTIONS) > 150
    assert "eha_core.simulate.simulate" in FUNCTIONS
    assert "eha_core.identify.tfest.tfest" in FUNCTIONS
    assert not any(label.split(".")[-1].startswith("_") for label in FUNCTIONS)


@pytest.mark.parametrize("label", sorted(FUNCTIONS))
def test_every_parameter_is_documented(label):
    function = FUNCTIONS[label]
    assert inspect.getdoc(function), f"{label} has no docstring"
    missing = undocumented(function)
    assert not missing, f"{label}: parameters not documented: {', '.join(missing)}"


def test_the_rule_catches_a_missing_parameter():
    def documented(a, b, *args, c=1, **kwargs):
        """Add.

        Parameters
        ----------
        a, b : float
            The terms.
        c : int
            Ignored.
        """

    def forgotten(a, b, c=1):
        """Add.

        Parameters
        ----------
        a : float
            The first term.
        """

    def short(a, b):
        """Add ``a`` and b."""

    assert undocumented(documented) == []
    assert undocumented(forgotten) == ["b", "c"]
    assert undocumented(short) == ["b"]


# -- the maps of the packages --------------------------------------------------------------------

MAP_ENTRY = re.compile(r"^\s{2,}(?P<name>[A-Za-z_][\w.]*)\s+--\s+\S", re.MULTILINE)


def map_entries(package: str) -> list[str]:
    return MAP_ENTRY.findall(importlib.import_module(package).__doc__ or "")


@pytest.mark.parametrize("package", ["eha_core", "eha_core.identify"])
def test_every_name_of_the_map_exists(package):
    """``module -- ...`` is a module of the package; ``module.name -- ...`` an attribute of that module."""
    entries = map_entries(package)
    assert len(entries) >= 10, f"{package}'s docstring has no map"
    missing = []
    for entry in entries:
        path = f"{package}.{entry}"
        try:
            importlib.import_module(path)
            continue
        except ImportError:
            pass
        module_name, _, attribute = path.rpartition(".")
        try:
            if not hasattr(importlib.import_module(module_name), attribute):
                missing.append(entry)
        except ImportError:
            missing.append(entry)
    assert not missing, f"{package}'s map names what does not exist: {missing}"
