"""The expression language of a guarded xacro expansion (:mod:`hil.description.xacro_guard`):
``${...}`` and ``$(eval ...)`` parsed with :mod:`ast` and interpreted here, never by
Python's ``eval``: numbers, strings, lists, tuples and dicts; arithmetic, comparisons,
boolean logic, conditional expressions; indexing; property names; ``namespace.name`` on
xacro's namespaces and dotified YAML (no name starting with ``_``); calls of xacro's own
functions, ``math``'s, a list of harmless builtins (:data:`BUILTINS`) and the string methods
of :data:`STRING_METHODS` on a string. Nothing else: no attribute of any other object, no
comprehension, lambda or f-string; results bounded (:data:`MAX_ITEMS`,
:data:`MAX_INT_BITS`).
"""

from __future__ import annotations

import ast
import math
import operator
from collections.abc import Iterator
from dataclasses import dataclass

#: the longest sequence an expression may build, and the largest integer (bits)
MAX_ITEMS = 1_000_000
MAX_INT_BITS = 100_000
#: an expression longer than this is refused (characters)
MAX_EXPRESSION = 10_000

#: the builtins an expression may call (xacro exposes these and a few more; not ``type``,
#: ``vars``, ``isinstance``, ``issubclass``, ``hash``)
BUILTINS = {f.__name__: f for f in (
    abs, all, any, bool, complex, dict, divmod, enumerate, filter, float, frozenset, int,
    len, list, map, max, min, ord, repr, reversed, round, set, slice, sorted, str, sum,
    tuple, zip)}

_BINARY = {ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul,
           ast.Div: operator.truediv, ast.FloorDiv: operator.floordiv, ast.Mod: operator.mod,
           ast.Pow: operator.pow, ast.LShift: operator.lshift, ast.RShift: operator.rshift,
           ast.BitAnd: operator.and_, ast.BitOr: operator.or_, ast.BitXor: operator.xor}
_UNARY = {ast.UAdd: operator.pos, ast.USub: operator.neg, ast.Not: operator.not_,
          ast.Invert: operator.invert}
_COMPARE = {ast.Eq: operator.eq, ast.NotEq: operator.ne, ast.Lt: operator.lt,
            ast.LtE: operator.le, ast.Gt: operator.gt, ast.GtE: operator.ge,
            ast.In: lambda a, b: a in b, ast.NotIn: lambda a, b: a not in b,
            ast.Is: operator.is_, ast.IsNot: operator.is_not}

#: the methods a string's value may call: each reads the string and returns at most its
#: length in items (Enactic's openarm_description calls ``prefix.find('right_')``). Not
#: ``format``/``format_map`` (a format string reaches any attribute of its arguments), nor
#: those whose result grows with an argument (``replace``, ``join``, ``center``, ``ljust``,
#: ``rjust``, ``zfill``, ``expandtabs``)
STRING_METHODS = frozenset({
    "find", "rfind", "index", "rindex", "count", "startswith", "endswith", "lower", "upper",
    "casefold", "swapcase", "capitalize", "title", "strip", "lstrip", "rstrip", "split",
    "rsplit", "splitlines", "partition", "rpartition", "removeprefix", "removesuffix",
    "isdigit", "isdecimal", "isnumeric", "isalpha", "isalnum", "isspace", "islower",
    "isupper", "istitle", "isidentifier"})


class Refused(ValueError):
    """An expression or a file the guard does not allow."""


@dataclass(frozen=True)
class _StringMethod:
    """``text.name``, one of STRING_METHODS, as an expression's call may call it."""

    text: str
    name: str

    def __call__(self, *args, **kwargs):
        return getattr(self.text, self.name)(*args, **kwargs)


def evaluate(expression: str, symbols, extra_functions=()) -> object:
    """``expression`` evaluated as the module doc says, names looked up in ``symbols``
    (xacro's property table, or any mapping); Refused for anything else."""
    if len(expression) > MAX_EXPRESSION:
        raise Refused(f"an expression of {len(expression)} characters, over {MAX_EXPRESSION}")
    try:
        tree = ast.parse(expression.strip(), "<expression>", "eval")
    except RecursionError:
        raise Refused("an expression nested too deeply") from None
    try:
        return _Interpreter(symbols, extra_functions).value(tree.body)
    except RecursionError:
        raise Refused("an expression nested too deeply") from None


class _Interpreter:
    def __init__(self, symbols, extra_functions):
        import xacro
        self.symbols = symbols
        self.namespaces = (xacro.NameSpace, xacro.YamlDictWrapper)
        callables = [*BUILTINS.values(), *extra_functions]
        callables += [v for k, v in vars(math).items() if callable(v) and not k.startswith("_")]
        callables += [v for v in _xacro_functions(xacro)]
        self.callables = {id(f) for f in callables}

    def value(self, node):
        method = getattr(self, f"_{type(node).__name__}", None)
        if method is None:
            raise Refused(f"{type(node).__name__} is not allowed in a description's "
                          "expression (arithmetic, comparisons, properties and the "
                          "math/xacro functions are)")
        return method(node)

    def _Constant(self, node):
        return node.value

    def _Name(self, node):
        if node.id.startswith("_"):
            raise Refused(f"name '{node.id}' is not allowed")
        try:
            return self.symbols[node.id]
        except KeyError:
            raise NameError(f"name '{node.id}' is not defined") from None

    def _Attribute(self, node):
        owner = self.value(node.value)
        if isinstance(owner, str) and node.attr in STRING_METHODS:
            return _StringMethod(owner, node.attr)
        if node.attr.startswith("_") or not isinstance(owner, self.namespaces):
            raise Refused(f"attribute '{node.attr}' is not allowed (only a namespace's, "
                          "dotified YAML's names and a string's reading methods are)")
        return getattr(owner, node.attr)

    def _Subscript(self, node):
        return self.value(node.value)[self.value(node.slice)]

    def _Slice(self, node):
        return slice(*(None if part is None else self.value(part)
                       for part in (node.lower, node.upper, node.step)))

    def _Tuple(self, node):
        return tuple(self.value(item) for item in node.elts)

    def _List(self, node):
        return [self.value(item) for item in node.elts]

    def _Dict(self, node):
        if any(key is None for key in node.keys):
            raise Refused("'**' is not allowed in a description's expression")
        return {self.value(k): self.value(v) for k, v in zip(node.keys, node.values)}

    def _BinOp(self, node):
        left, right = self.value(node.left), self.value(node.right)
        op = type(node.op)
        if op not in _BINARY:
            raise Refused(f"operator {op.__name__} is not allowed")
        _check_size(op, left, right)
        return _bounded(_BINARY[op](left, right))

    def _UnaryOp(self, node):
        return _UNARY[type(node.op)](self.value(node.operand))

    def _BoolOp(self, node):
        result = None
        for item in node.values:
            result = self.value(item)
            if isinstance(node.op, ast.And) != bool(result):
                return result
        return result

    def _Compare(self, node):
        left = self.value(node.left)
        for op, comparator in zip(node.ops, node.comparators):
            right = self.value(comparator)
            if not _COMPARE[type(op)](left, right):
                return False
            left = right
        return True

    def _IfExp(self, node):
        return self.value(node.body) if self.value(node.test) else self.value(node.orelse)

    def _Call(self, node):
        function = self.value(node.func)
        if not isinstance(function, _StringMethod) and id(function) not in self.callables:
            raise Refused(f"calling {getattr(function, '__name__', type(function).__name__)} "
                          "is not allowed (math's, xacro's, a few builtins and a string's "
                          "reading methods are)")
        if any(isinstance(a, ast.Starred) for a in node.args):
            raise Refused("'*' is not allowed in a description's expression")
        args = [self.value(a) for a in node.args]
        if any(k.arg is None for k in node.keywords):
            raise Refused("'**' is not allowed in a description's expression")
        kwargs = {k.arg: self.value(k.value) for k in node.keywords}
        return _bounded(function(*args, **kwargs))


def _xacro_functions(xacro) -> Iterator:
    """xacro's own functions (its namespace ``xacro`` and their deprecated direct names)."""
    symbols = xacro._global_symbols
    namespace = symbols.get("xacro", {})
    yield from (v for v in dict.values(namespace) if callable(v))
    yield from (symbols[name] for name in ("load_yaml", "abs_filename", "dotify")
                if name in symbols)


def _check_size(op, left, right) -> None:
    """Refuse what would take the machine's memory before it is computed."""
    if op is ast.Pow and isinstance(left, int) and isinstance(right, int) and right > 0 \
            and left not in (0, 1, -1) and left.bit_length() * right > MAX_INT_BITS:
        raise Refused(f"{left} ** {right} is larger than {MAX_INT_BITS} bits")
    if op is ast.LShift and isinstance(right, int) and right > MAX_INT_BITS:
        raise Refused(f"<< {right} is larger than {MAX_INT_BITS} bits")
    if op is ast.Mult:
        for sequence, count in ((left, right), (right, left)):
            if isinstance(sequence, (str, bytes, list, tuple)) and isinstance(count, int) \
                    and len(sequence) * count > MAX_ITEMS:
                raise Refused(f"a sequence of {len(sequence) * count} items, over {MAX_ITEMS}")


def _bounded(result):
    if isinstance(result, (str, bytes, list, tuple, dict, set, frozenset)) \
            and len(result) > MAX_ITEMS:
        raise Refused(f"a result of {len(result)} items, over {MAX_ITEMS}")
    if isinstance(result, range) and len(result) > MAX_ITEMS:
        raise Refused(f"a range of {len(result)} items, over {MAX_ITEMS}")
    return result
