"""README's Pendulum example runs and prints what README says it prints."""

from __future__ import annotations

import contextlib
import io
import re
from pathlib import Path

from example_specs.at_least import AtLeast
from specguard.testing import parametrize_with_checks

README = Path(__file__).resolve().parent.parent / "README.md"


def test_readme_language_example_prints_what_it_shows():
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(encoding="utf-8"), flags=re.S)
    example = next(b for b in blocks if "sg.make_env(pendulum, tree)" in b)
    shown = [line[2:] for line in example.splitlines() if line.startswith("# ")]
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        exec(compile(example, str(README), "exec"), {})
    assert out.getvalue().splitlines() == shown


def test_readme_goal_spec_example_collects_one_item_per_goal(pytester):
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(encoding="utf-8"), flags=re.S)
    first = next(b for b in blocks if "test_pendulum_specs.py" in b)
    second = next(b for b in blocks if "def test_weighted" in b)
    pytester.makepyfile(test_pendulum_specs=first + "\n\n" + second)
    result = pytester.runpytest("-p", "no:cacheprovider", "-q", "-rs")
    result.assert_outcomes(skipped=4)
    result = pytester.runpytest("-p", "no:cacheprovider", "--collect-only", "-q")
    result.stdout.fnmatch_lines(
        [
            "test_pendulum_specs.py::test_refined[[]pendulum[]]",
            "test_pendulum_specs.py::test_refined[[]stabilization[]]",
            "test_pendulum_specs.py::test_weighted[[]pendulum[]]",
            "test_pendulum_specs.py::test_weighted[[]position[]]",
        ]
    )


# -- README's "Writing an operator": the worked example is a tested file ----------------


def test_readme_operator_example_is_the_tested_file():
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(encoding="utf-8"), flags=re.S)
    shown = next(b for b in blocks if "class AtLeast(Node)" in b)
    source = (README.parent / "example_specs" / "at_least.py").read_text(encoding="utf-8")
    for line in shown.splitlines():
        if line.strip() and not line.lstrip().startswith("..."):
            assert line in source, f"README shows a line the file does not have: {line!r}"


@parametrize_with_checks([AtLeast])
def test_readme_operator_passes_the_contract_kit(operator, check):
    check(operator)


def test_readme_layout_names_every_module_under_its_part():
    from pathlib import Path

    import specguard

    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    table = readme.split("### Layout", 1)[1].split("\n\n")[2]
    rows = {}
    for line in table.splitlines()[2:]:
        part, modules = line.strip("|").split("|", 1)
        rows[part.strip().strip("`").rstrip("/")] = modules
    package = Path(specguard.__file__).parent
    missing = []
    for path in sorted(package.rglob("*.py")):
        relative = path.relative_to(package)
        if path.name == "__init__.py" or "__pycache__" in relative.parts:
            continue
        part = relative.parts[0] if len(relative.parts) > 1 else None
        row = rows.get({"contract": "public tools", "utils": "base"}.get(part, part)) if part else table
        if row is None or f"`{path.stem}`" not in row:
            missing.append(str(relative))
    assert missing == [], f"README's layout table does not list: {missing}"
