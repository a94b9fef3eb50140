"""User modules that cannot be imported, each its own way, for ``"module:Class"`` algorithms and ``"module:Id"`` envs.

:data:`CASES` pairs the module part of such a string with what the one error says of it;
:func:`write_bad_modules` writes the modules it names to a folder (put it on ``sys.path``).
"""

from __future__ import annotations

from pathlib import Path

SOURCES = {
    "sg_raises_at_import": "raise RuntimeError('boom at import')\n",
    "sg_syntax_error": "def f(:\n",
    "sg_exits_at_import": "import sys\nsys.exit(3)\n",
    "sg_os_exits_at_import": "import os\nos._exit(4)\n",
}

CASES = [
    ("", "it names no module before ':'"),
    (".rel", "its module '.rel' is relative; name it from its top package (package.rel)"),
    ("sg_raises_at_import", "RuntimeError: boom at import"),
    ("sg_syntax_error", "SyntaxError: "),
    ("sg_exits_at_import", "importing 'sg_exits_at_import' called sys.exit(3)"),
    ("sg_os_exits_at_import", "importing 'sg_os_exits_at_import' called os._exit(4)"),
]
"""``(module part, what the message says of it)``, one per way an import fails."""


def write_bad_modules(folder: Path) -> None:
    for name, source in SOURCES.items():
        (folder / f"{name}.py").write_text(source)
