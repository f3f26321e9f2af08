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

* every expression is parsed with :mod:`ast` and interpreted by
  :mod:`hil.description.xacro_expressions` (:func:`evaluate`): arithmetic, properties, the
  math/xacro functions, a few builtins and a string's reading methods, nothing else, results
  bounded.
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

import contextvars
import io
import os
import re
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from hil.description.packages import own_package
from hil.description.xacro_expressions import Refused, evaluate
from hil.errors import HilError
from hil.input_files import file_problem, read_input_file, refusal_text

#: a character that makes an include's name a glob (xacro's get_include_files: '[*[?]+')
_GLOB = re.compile(r"[*?\[]")
#: the files xacro.load_yaml reads (by name: xacro reads any other as XML)
_YAML_SUFFIXES = (".yaml", ".yml", ".json")
#: the environment variable naming the variables a description may read
ALLOWED_ENV_VARIABLE = "HIL_XACRO_ENV"
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
