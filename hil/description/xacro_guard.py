"""xacro with no way out of the description: expressions evaluated by an interpreter of the
arithmetic a description needs, files read only where the user allowed, environment
variables only those the user named.

xacro (ROS 2's, the PyPI package) evaluates ``${...}`` and ``$(eval ...)`` with Python's
``eval``, guarded by a check of the names the expression's own code uses: a comprehension's
inner code object escapes it (``[c for c in ().__class__.__base__.__subclasses__()]`` reaches
``os.system``), and ``$(eval ...)`` runs with Python's builtins (``open``). It includes any
file (``/dev/zero``: memory until the machine fails), reads YAML from anywhere
(``xacro.load_yaml``) and any environment variable (``$(env ...)``).

While :func:`guarded` is in force (hil enters it around every expansion):

* every expression is parsed with :mod:`ast` and interpreted here (:func:`evaluate`): numbers,
  strings, lists, tuples and dicts; arithmetic, comparisons, boolean logic, conditional
  expressions; indexing; property names; ``namespace.name`` on xacro's namespaces and
  dotified YAML (no name starting with ``_``); calls of xacro's own functions, ``math``'s and
  a list of harmless builtins (:data:`BUILTINS`). Nothing else: no attribute of any other
  object, no comprehension, lambda or f-string; results bounded (:data:`MAX_ITEMS`,
  :data:`MAX_INT_BITS`).
* every file xacro opens (an include, each file an include's glob matches,
  ``xacro.load_yaml``) must be a regular file of at most
  :data:`hil.input_files.MAX_FILE_BYTES` inside the allowed folders: the description's own
  folder and the package search path (``--package-path``, ``$HIL_PACKAGE_PATH``,
  ``$ROS_PACKAGE_PATH``), and is read as every file a user names is
  (:func:`hil.input_files.read_input_file`: no XML document type, nesting counted), where
  xacro's own ``open()`` expanded an include's entities.
* ``$(env NAME)`` and ``$(optenv NAME ...)`` read only variables listed in
  ``$HIL_XACRO_ENV`` (comma-separated); any other is "not set" (``optenv``: its default).
"""

from __future__ import annotations

import ast
import contextvars
import io
import math
import operator
import os
import re
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from hil.description.packages import own_package
from hil.errors import HilError
from hil.input_files import file_problem, read_input_file, refusal_text

#: a character that makes an include's name a glob (xacro's get_include_files: '[*[?]+')
_GLOB = re.compile(r"[*?\[]")
#: the files xacro.load_yaml reads (by name: xacro reads any other as XML)
_YAML_SUFFIXES = (".yaml", ".yml", ".json")
#: the environment variable naming the variables a description may read
ALLOWED_ENV_VARIABLE = "HIL_XACRO_ENV"
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


class Refused(ValueError):
    """An expression or a file the guard does not allow."""


@dataclass(frozen=True)
class Allowed:
    """What a description may reach: folders (resolved) and environment variables."""

    folders: tuple[Path, ...]
    variables: frozenset[str]

    @classmethod
    def of(cls, description: Path, package_folders) -> Allowed:
        """The description's folder (its package's, where it is in one: ``../meshes``
        beside ``urdf/``), the package path's folders, and $HIL_XACRO_ENV's variables."""
        package = own_package(description)
        folders = (package or Path(description).resolve().parent,
                   *(Path(f).resolve() for f in package_folders))
        names = os.environ.get(ALLOWED_ENV_VARIABLE, "")
        return cls(folders, frozenset(n.strip() for n in names.split(",") if n.strip()))

    def check_place(self, path: str) -> None:
        """Refused unless ``path`` is inside one of the folders."""
        if not any(Path(path).resolve().is_relative_to(folder) for folder in self.folders):
            raise Refused(f"'{path}' is outside the description's folder and the package "
                          "search path: hil reads no file there (add its folder with "
                          "--package-path to allow it)")

    def check_file(self, path: str) -> None:
        """Refused unless ``path`` is inside one of the folders and, where it exists, a
        regular file of at most MAX_FILE_BYTES (file_problem); a missing one xacro names
        itself, where the include is not ``optional``."""
        self.check_place(path)
        problem = file_problem(Path(path)) if os.path.exists(path) else None
        if problem:
            raise Refused(f"'{path}' {problem}")


_allowed: contextvars.ContextVar[Allowed | None] = contextvars.ContextVar("xacro_allowed",
                                                                          default=None)


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
        if node.attr.startswith("_") or not isinstance(owner, self.namespaces):
            raise Refused(f"attribute '{node.attr}' is not allowed (only a namespace's or "
                          "dotified YAML's names are)")
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
        if id(function) not in self.callables:
            raise Refused(f"calling {getattr(function, '__name__', type(function).__name__)} "
                          "is not allowed (math's, xacro's and a few builtins are)")
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


# --- what xacro calls instead, while guarded -----------------------------------------------

def _install(xacro) -> None:
    """Replace xacro's evaluation, file and environment access with the guarded ones
    (once; each checks the Allowed of the expansion in force, and refuses all outside
    one)."""
    from xacro import substitution_args

    if getattr(xacro, "_hil_guarded", False):
        return
    original_abs_filename = xacro.abs_filename_spec
    original_includes = xacro.get_include_files

    def safe_eval(expr, globals, locals=None):
        try:
            return evaluate(expr, globals if locals is None else _Chain(locals, globals))
        except Refused as exc:
            raise xacro.XacroException(str(exc)) from None

    def check(method, path: str) -> None:
        try:
            method(_current(), path)
        except Refused as exc:
            raise xacro.XacroException(str(exc)) from None

    def abs_filename_spec(filename_spec):
        path = original_abs_filename(filename_spec)
        if glob := _GLOB.search(path):
            # an include of every file a glob matches (xacro's get_include_files): the folder
            # its fixed part names must be allowed; each match is checked as a file below
            check(Allowed.check_place, path[:glob.start()])
        else:
            check(Allowed.check_file, path)
        return path

    def get_include_files(filename_spec, symbols):
        for filename in original_includes(filename_spec, symbols):
            check(Allowed.check_file, filename)
            yield filename

    def read_file(name, mode="r", *args, **kwargs):
        # xacro reads a file (an include: xacro.parse; xacro.load_yaml) by calling open() by
        # its module's name: hil's reader instead, as for the description itself (no
        # DOCTYPE: an include's entities were expanded; nesting counted). Writing (xacro's
        # own --output, never hil's) is open()'s.
        if mode != "r" or not os.path.exists(name):
            # a missing file: open()'s error, which xacro names (or skips: optional="true")
            return open(name, mode, *args, **kwargs)
        syntax = "yaml" if Path(name).suffix.lower() in _YAML_SUFFIXES else "xml"
        what = "YAML file" if syntax == "yaml" else "included file"
        try:
            return io.StringIO(read_input_file(Path(name), what, hint="", syntax=syntax))
        except HilError as exc:
            raise xacro.XacroException(refusal_text(exc)) from None

    def eval_env(name):
        if name not in _current().variables or name not in os.environ:
            raise substitution_args.SubstitutionException(
                f"environment variable {name} is not set (hil reads only the variables "
                f"${ALLOWED_ENV_VARIABLE} names)")
        return os.environ[name]

    def eval_optenv(name, default=""):
        return os.environ[name] if name in _current().variables and name in os.environ \
            else default

    def eval_substitution(s, context):
        arguments = context.setdefault("arg", {})
        functions = {
            "arg": lambda name: substitution_args.convert_value(
                substitution_args._eval_arg(name, args=arguments), "auto"),
            "dirname": lambda: substitution_args._eval_dirname(context["filename"])}
        names = {**{k: v for k, v in substitution_args._eval_dict.items()
                    if not k.startswith("_")}, **functions}
        lookup = _Chain(names, {k: substitution_args.convert_value(v, "auto")
                                for k, v in arguments.items()})
        try:
            return str(evaluate(s, lookup, functions.values()))
        except Refused as exc:
            raise substitution_args.SubstitutionException(f"$(eval {s}): {exc}") from None

    xacro.safe_eval = safe_eval
    xacro.abs_filename_spec = abs_filename_spec
    xacro.get_include_files = get_include_files
    xacro.open = read_file
    substitution_args._eval_env = eval_env
    substitution_args._eval_optenv = eval_optenv
    substitution_args._eval = eval_substitution
    xacro._hil_guarded = True


class _Chain:
    """Names looked up in the first mapping, then the second."""

    def __init__(self, first, second):
        self.first, self.second = first, second

    def __getitem__(self, key):
        try:
            return self.first[key]
        except KeyError:
            return self.second[key]


def _current() -> Allowed:
    allowed = _allowed.get()
    if allowed is None:         # xacro used outside hil's expansion: nothing is allowed
        return Allowed((), frozenset())
    return allowed


@contextmanager
def guarded(allowed: Allowed):
    """xacro expands under ``allowed`` inside the block (the module doc)."""
    import xacro

    _install(xacro)
    token = _allowed.set(allowed)
    try:
        yield
    finally:
        _allowed.reset(token)
