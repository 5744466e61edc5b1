"""Errors are values: no code reads an exception's message back, and refusals are not hand-formatted.

A refusal is a :class:`eha_core._checks.FieldError` (``field``, ``value``,
``what``); its message is rendered from those, and code that needs a fact about
the problem reads an attribute (``DataError.missing_columns``), never the
prose. Two checks over the source of ``eha_core`` and ``eha_app`` (with
:mod:`ast`, so comments and docstrings do not count):

* :func:`prose_readings`: a comparison or a search on an exception's text,
  ``str(exc)``, ``exc.args``, ``exc.what``, ``exc.message``, ``exc.text``
  (or a variable holding one of them): ``.startswith``, ``.endswith``,
  ``in``, ``==`` against a literal, ``.split(sep)``, ``.replace``, ``re.match``...
  Rendering the text for display (``str(exc)``, ``" ".join(str(exc).split())``)
  is fine.
* :func:`hand_formatted_refusals`: a string literal that writes
  ``... is not allowed ...`` itself, outside :mod:`eha_core._checks` (the one
  place that formats the sentence).
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("eha_core", "eha_app")

#: The one module that writes "NAME = VALUE is not allowed: WHAT".
FORMATTER = "eha_core/_checks.py"

#: Attributes of an exception that hold (part of) its message.
MESSAGE_ATTRIBUTES = frozenset({"args", "what", "message", "text", "msg", "allowed"})
#: String methods that look inside a text (``split``/``rsplit`` only with a separator).
TEXT_READERS = frozenset({"startswith", "endswith", "find", "rfind", "index", "rindex", "count", "partition",
                          "rpartition", "replace", "removeprefix", "removesuffix", "split", "rsplit"})
REGEX_READERS = frozenset({"match", "search", "fullmatch", "findall", "finditer", "sub", "subn", "split"})


_FUNCTIONS = (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)
#: Parameters that receive an exception's message (a job's ``fail(message)`` callback, say).
MESSAGE_PARAMETERS = frozenset({"message"})


def _scopes(tree: ast.AST):
    """The module and every function in it, each analysed on its own."""
    yield tree
    for node in ast.walk(tree):
        if isinstance(node, _FUNCTIONS):
            yield node


def _own_nodes(scope: ast.AST) -> list[ast.AST]:
    """The nodes of ``scope``, its nested functions' bodies left out (they are scopes of their own)."""
    nodes, todo = [], list(ast.iter_child_nodes(scope))
    while todo:
        node = todo.pop()
        nodes.append(node)
        if isinstance(node, _FUNCTIONS):
            # the defaults and decorators are evaluated in this scope, the body is not
            outside = [*node.args.defaults, *node.args.kw_defaults, *getattr(node, "decorator_list", [])]
            todo.extend(n for n in outside if n is not None)
            continue
        todo.extend(ast.iter_child_nodes(node))
    return nodes


def _assignments(nodes):
    """``(target name, value)`` of the simple assignments among ``nodes``."""
    for node in nodes:
        if isinstance(node, ast.Assign):
            for target in node.targets:
                if isinstance(target, ast.Name):
                    yield target.id, node.value
        elif isinstance(node, (ast.AnnAssign, ast.AugAssign, ast.NamedExpr)) and node.value is not None:
            if isinstance(node.target, ast.Name):
                yield node.target.id, node.value


class _Scope:
    """Which expressions of one function (or module) hold an exception's message text."""

    def __init__(self, scope: ast.AST):
        self.nodes = _own_nodes(scope)
        self.exceptions = {n.name for n in self.nodes if isinstance(n, ast.ExceptHandler) and n.name}
        arguments = scope.args.posonlyargs + scope.args.args + scope.args.kwonlyargs \
            if isinstance(scope, _FUNCTIONS) else []
        self.texts: set[str] = {a.arg for a in arguments if a.arg in MESSAGE_PARAMETERS}
        assignments = list(_assignments(self.nodes))
        while True:                           # names assigned from a message, transitively
            more = {name for name, value in assignments if name not in self.texts and self.holds_text(value)}
            if not more:
                break
            self.texts |= more

    def _is_exception(self, node) -> bool:
        return isinstance(node, ast.Name) and node.id in self.exceptions

    def holds_text(self, expr: ast.AST) -> bool:
        """Whether ``expr`` is, or is computed from, an exception's message."""
        for node in ast.walk(expr):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in (
                    "str", "repr", "format") and node.args and self._is_exception(node.args[0]):
                return True
            if isinstance(node, ast.Attribute) and node.attr in MESSAGE_ATTRIBUTES and self._is_exception(node.value):
                return True
            if isinstance(node, ast.FormattedValue) and self._is_exception(node.value):
                return True
            if isinstance(node, ast.Name) and node.id in self.texts:
                return True
        return False

    def readings(self):
        """``(line, what)`` of every place that looks inside a message."""
        for node in self.nodes:
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute):
                func = node.func
                if func.attr in TEXT_READERS and self.holds_text(func.value) and (
                        func.attr not in ("split", "rsplit") or node.args or node.keywords):
                    yield node.lineno, f".{func.attr}() on an exception's text"
                elif (isinstance(func.value, ast.Name) and func.value.id == "re" and func.attr in REGEX_READERS
                      and any(self.holds_text(a) for a in node.args)):
                    yield node.lineno, f"re.{func.attr}() on an exception's text"
            elif isinstance(node, ast.Compare):
                operands = [node.left, *node.comparators]
                for op, left, right in zip(node.ops, operands[:-1], operands[1:], strict=True):
                    if isinstance(op, (ast.In, ast.NotIn)) and (self.holds_text(left) or self.holds_text(right)):
                        yield node.lineno, "'in' on an exception's text"
                    elif isinstance(op, (ast.Eq, ast.NotEq)) and any(
                            self.holds_text(a) and isinstance(b, (ast.Constant, ast.JoinedStr))
                            for a, b in ((left, right), (right, left))):
                        yield node.lineno, "'==' between an exception's text and a literal"


def prose_readings(source: str) -> list[tuple[int, str]]:
    """``(line, what)`` of the places where ``source`` reads an exception's message back."""
    tree = ast.parse(source)
    found = {hit for scope in _scopes(tree) for hit in _Scope(scope).readings()}
    return sorted(found)


def _docstrings(tree: ast.AST) -> set[int]:
    ids = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and node.body:
            first = node.body[0]
            if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant) and isinstance(
                    first.value.value, str):
                ids.add(id(first.value))
    return ids


def hand_formatted_refusals(source: str) -> list[tuple[int, str]]:
    """``(line, text)`` of the string literals (docstrings aside) that write "is not allowed" themselves."""
    tree = ast.parse(source)
    docstrings = _docstrings(tree)
    return sorted({(node.lineno, node.value) for node in ast.walk(tree)
                   if isinstance(node, ast.Constant) and isinstance(node.value, str)
                   and "is not allowed" in node.value and id(node) not in docstrings})


def _sources():
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            yield path.relative_to(ROOT).as_posix(), path.read_text(encoding="utf-8")


# -- the checkers on planted examples --------------------------------------------------------

PLANTED_READINGS = '''
def f(read):
    try:
        read()
    except ValueError as exc:
        if str(exc).startswith("no column"):            # 6
            return 1
        if exc.what.endswith("rows"):                   # 8
            return 2
        message = " ".join(str(exc).split())
        if "the file has" in message:                   # 11
            return 3
        text = message.lower()
        if text == "bad":                               # 14
            return 4
        if exc.args[0].split(":")[0] != "x":            # 16
            return 5
        return str(exc).replace("a = ", "--a = ")       # 18
    except KeyError as err:
        import re
        return re.match("x", str(err))                  # 21


def fail(message):
    return "to" if message.startswith("to t") else "from"   # 25
'''

PLANTED_FINE = '''
def f(read, exc_list):
    try:
        read()
    except ValueError as exc:
        show(" ".join(str(exc).split()))
        if exc.missing_columns:
            return exc.render(label="--data")
        if "x" in exc_list or str(read).startswith("a"):
            return None
        raise


def parse(text):
    return float(text.strip().replace(",", "."))       # what the user typed, not a message
'''


def test_prose_readings_finds_every_planted_one():
    lines = sorted({line for line, _ in prose_readings(PLANTED_READINGS)})
    assert lines == [6, 8, 11, 14, 16, 18, 21, 25]


def test_prose_readings_leaves_display_and_attributes_alone():
    assert prose_readings(PLANTED_FINE) == []


def test_hand_formatted_refusals_finds_literals_not_docstrings():
    source = '''
"""Module: ``x = 1 is not allowed: ...`` in a docstring is fine."""
def f(name, value):
    """So is this: a = b is not allowed: c."""
    raise ValueError(f"{name} = {value} is not allowed: use 1")
X = "y = 2 is not allowed with z: " + "no"
'''
    assert [line for line, _ in hand_formatted_refusals(source)] == [5, 6]


# -- the checks on the code ----------------------------------------------------------------

def test_no_code_reads_an_exception_message_back():
    found = [f"{path}:{line}: {what}" for path, source in _sources() for line, what in prose_readings(source)]
    assert not found, ("read the error's attributes (field, value, what, missing_columns...) instead:\n"
                       + "\n".join(found))


def test_refusals_are_formatted_in_one_place():
    counts = {path: len(hand_formatted_refusals(source)) for path, source in _sources()}
    counts.pop(FORMATTER)
    unexpected = {p: n for p, n in counts.items() if n}
    assert not unexpected, (f"these modules write 'is not allowed' themselves: {unexpected}; raise "
                            "eha_core.errors.FieldError (or not_allowed) instead")



def test_the_one_formatter_writes_the_sentence():
    # the check above looks for the sentence where it is written; it must still be written there
    assert hand_formatted_refusals((ROOT / FORMATTER).read_text(encoding="utf-8"))
