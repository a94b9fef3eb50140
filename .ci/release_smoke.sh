#!/usr/bin/env bash
# The release, as someone installing from an index gets it: build the sdist and the wheel of both
# distributions (specguard and plugins/' specguard-plugins), check their metadata (`twine check --strict`)
# and that each archive ships LICENSE, then install the wheels (not editable) in a fresh venv on the oldest
# and the newest supported Python and, from a directory outside the checkout, run `pytest --help`,
# `specguard --help` and one tiny spec under `pytest --goal-specs` (128 training steps).
#
# Usage: .ci/release_smoke.sh [PYTHON ...]   (default: python3.11 python3.13, the oldest and the newest)
#        .ci/release_smoke.sh --build DIR      build and check the four archives into DIR, and stop there
#        .ci/release_smoke.sh --dist DIR [PYTHON ...]   install the archives built before into DIR (no build)
# (.ci/run builds once, lets the suite's packaging tests read the sdists, then installs the wheels.)
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
BUILD_ONLY=""
BUILT=""
case "${1:-}" in
--build | --dist)
    [ $# -ge 2 ] || { echo "release smoke: $1 needs a folder" >&2; exit 2; }
    [ "$1" = --build ] && BUILD_ONLY=$2 || BUILT=$2
    shift 2
    ;;
esac
NAMES=("$@")
[ ${#NAMES[@]} -gt 0 ] || NAMES=(python3.11 python3.13)

# The interpreter a name runs: on PATH, or else pyenv's installed version of it when pyenv has not selected
# that version (its shim then refuses to run); none is an error, never a Python skipped in silence.
interpreter() {
    if "$1" -c "" 2>/dev/null; then
        command -v "$1"
        return
    fi
    local found
    found=$(find "${PYENV_ROOT:-$HOME/.pyenv}/versions" -maxdepth 3 -path "*/bin/$1" 2>/dev/null | sort -V | tail -1)
    if [ -z "$found" ]; then
        echo "release smoke: no $1 on PATH nor under pyenv" >&2
        exit 2
    fi
    echo "$found"
}
PYTHONS=()
for name in "${NAMES[@]}"; do
    PYTHONS+=("$(interpreter "$name")")
done

# Nothing of the checkout may be importable from the smoke venvs.
unset PYTHONPATH
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
DIST=${BUILD_ONLY:-${BUILT:-$WORK/dist}}

if [ -n "$BUILT" ]; then
    echo "release smoke: the archives built before, in $BUILT: $(cd "$BUILT" && echo *)"
else
echo "release smoke: build and check (${PYTHONS[0]}; into $DIST)"
start=$SECONDS
mkdir -p "$DIST"
"${PYTHONS[0]}" -m venv "$WORK/tools"
"$WORK/tools/bin/pip" install -q -c constraints.txt build twine
"$WORK/tools/bin/python" -m build -q --outdir "$DIST" .
"$WORK/tools/bin/python" -m build -q --outdir "$DIST" plugins
"$WORK/tools/bin/twine" check --strict "$DIST"/*
"$WORK/tools/bin/python" - "$DIST"/* <<'EOF'
"""Each archive holds the license, there are exactly the four archives of the two distributions, and the sdists'
tests are none (specguard's read example_specs/ and docs/, which its sdist leaves out) or whole (the plugins')."""
import sys
import tarfile
import zipfile
from pathlib import Path

archives = [Path(a) for a in sys.argv[1:]]
kinds = sorted((a.name.split("-")[0], "wheel" if a.suffix == ".whl" else "sdist") for a in archives)
expected = [("specguard", "sdist"), ("specguard", "wheel"), ("specguard_plugins", "sdist"), ("specguard_plugins", "wheel")]
if kinds != expected:
    sys.exit(f"expected the sdist and the wheel of specguard and specguard_plugins, built: {[a.name for a in archives]}")
for archive in archives:
    if archive.suffix == ".whl":
        names = zipfile.ZipFile(archive).namelist()
        licensed = any(n.endswith(".dist-info/licenses/LICENSE") for n in names)
    else:
        names = tarfile.open(archive).getnames()
        licensed = any(n.count("/") == 1 and n.endswith("/LICENSE") for n in names)
    if not licensed:
        sys.exit(f"{archive.name}: no LICENSE among its {len(names)} files")
    if archive.suffix != ".whl":
        tests = sorted(n.split("/", 1)[1] for n in names if n.split("/")[1:2] == ["tests"] and n.endswith(".py"))
        folder = Path("plugins/tests") if archive.name.startswith("specguard_plugins-") else None
        expected = sorted(f"tests/{p.relative_to(folder).as_posix()}" for p in folder.rglob("*.py")) if folder else []
        if tests != expected:
            sys.exit(f"{archive.name}: ships the tests {tests}, expected {expected or 'none'}")
    print(f"{archive.name}: {len(names)} files, LICENSE included")
EOF
echo "release smoke: built and checked in $((SECONDS - start)) s"
fi
[ -z "$BUILD_ONLY" ] || exit 0

# The tiny spec: a plugin operator (found through its entry point) over Pendulum goals, 128 steps, 2 episodes.
mkdir "$WORK/project"
cat >"$WORK/project/test_release_smoke.py" <<'EOF'
import specguard as sg


@sg.goal_spec(expect={"either": 0.0})
def test_tiny():
    pendulum = sg.InitialEnv("Pendulum-v1", features=("x", "y", "omega"))
    tree = sg.AnyOf(
        sg.Goal("upright", x=(0.966, 1.0), y=(-0.259, 0.259)),
        sg.Goal("slow", omega=(-0.25, 0.25)),
        name="either",
    )
    budget = sg.Budget(timesteps=128, eval_episodes=2)
    return sg.Spec(pendulum, tree, budget=budget, hyperparameters={"n_steps": 64, "batch_size": 32, "n_epochs": 1})
EOF
printf '[pytest]\ngoal_specs_workers = 1\n' >"$WORK/project/pytest.ini"

for python in "${PYTHONS[@]}"; do
    start=$SECONDS
    venv="$WORK/venv-$(basename "$python")"
    "$python" -m venv "$venv"
    "$venv/bin/pip" install -q -c "$ROOT/constraints.txt" "$DIST"/*.whl
    installed=$((SECONDS - start))
    (
        cd "$WORK/project"
        "$venv/bin/python" -c "import specguard, specguard_plugins, sys; sys.exit(0 if 'site-packages' in specguard.__file__ and 'site-packages' in specguard_plugins.__file__ else f'imported from the checkout: {specguard.__file__}')"
        "$venv/bin/pytest" --help >/dev/null
        "$venv/bin/specguard" --help >/dev/null
        "$venv/bin/pytest" -p no:cacheprovider --goal-specs test_release_smoke.py | tee "$WORK/out.txt"
        grep -q "1 passed" "$WORK/out.txt" || { echo "release smoke ($python): the tiny spec did not pass"; exit 1; }
    )
    echo "release smoke ($python): installed in $installed s, whole check in $((SECONDS - start)) s"
    rm -rf "$venv"
done
