"""Play the CI recipe's steps locally on a tiny spec: main saves; a sabotaged pull request fails; an unchanged passes.

Takes the two commands of ``examples/ci/github-actions.yml`` (the main job's,
``--goal-specs-save main``, and the pull request's, ``--goal-specs-compare
main``) and plays the workflow in temporary project folders:

1. **main**: the project as it is; the main job's command passes and saves the baseline;
2. the run cache and the baselines travel to each pull request's folder (as the
   workflow's cache restore brings main's);
3. **pull request, sabotaged spec** (its goal narrowed to a region the policy
   rarely ends in): the comparison fails the pull request, the report says
   "dropped", and the extra seeds it trained are listed;
4. **pull request, unchanged spec**: passes, trains nothing (the baseline's own runs);
5. **pull request, renamed spec** (a change to the spec's identity, none to what
   it does): compared, passes.

Each step's Markdown report is appended to a job summary, as the workflow does.
The spec trains 128 steps per seed: the whole play takes about a minute on 2
cores. Exits 0 when every step did what the recipe promises, 1 otherwise
(saying which), 2 when the workflow's commands cannot be found.

Usage:
    python examples/ci/play_recipe.py [--keep DIR]
"""

from __future__ import annotations

import argparse
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

WORKFLOW = Path(__file__).resolve().parent / "github-actions.yml"
REPORT = "specguard-report"
TEST_FILE = "test_gate.py"
SPEC = """
import specguard as sg

TINY = {{"n_steps": 64, "batch_size": 32, "n_epochs": 1}}
pendulum = sg.InitialEnv("Pendulum-v1", features=("x", "y", "omega"))


@sg.goal_spec(expect={{"held": 0.0}})
def test_pendulum():
    # "held": where the pendulum ends an episode; x = cos(angle) spans [-1, 1]. The root holds until the end
    # (every episode runs its 200 steps), so "held" is judged where the episode's last state lies.
    tree = sg.Always(sg.Goal("held", x={region}), sg.Goal("slow", omega=(-8.0, 8.0)), name="pendulum")
    budget = sg.Budget(timesteps=128, eval_episodes=10, checkpoints=1)
    return sg.Spec(pendulum, tree, budget=budget, trainer=sg.SB3(hyperparameters=TINY), name={name!r})
"""
PROJECTS = {
    "main": {"region": (-1.0, 1.0), "name": "gate"},  # every final state: 100% of episodes
    "sabotaged": {"region": (0.9, 1.0), "name": "gate"},  # upright only: a tiny policy rarely ends there
    "unchanged": {"region": (-1.0, 1.0), "name": "gate"},
    "renamed": {"region": (-1.0, 1.0), "name": "gate-renamed"},
}


def workflow_commands(text: str) -> dict[str, list[str]]:
    """The main job's and the pull request's pytest commands in the workflow (``run: pytest --goal-specs ...``)."""
    found = {}
    for line in re.findall(r"^\s*run: (pytest --goal-specs .*)$", text, flags=re.MULTILINE):
        kind = (
            "main"
            if "--goal-specs-save main" in line
            else "pull request"
            if "--goal-specs-compare main" in line
            else None
        )
        if kind:
            found[kind] = shlex.split(line)
    return found


def project(root: Path, name: str) -> Path:
    folder = root / name
    folder.mkdir()
    settings = PROJECTS[name]
    (folder / TEST_FILE).write_text(SPEC.format(region=settings["region"], name=settings["name"]))
    (folder / "pytest.ini").write_text("[pytest]\n")
    return folder


def play(command: list[str], folder: Path, summary: Path) -> tuple[int, str, str]:
    """Run a workflow command in ``folder`` (this interpreter's pytest); append its report to the job summary."""
    argv = [sys.executable, "-m", *command, "-p", "no:cacheprovider", "-q"]
    done = subprocess.run(argv, cwd=folder, capture_output=True, text=True)
    report = folder / REPORT / "goal-specs.md"
    markdown = report.read_text() if report.is_file() else ""
    with summary.open("a") as f:
        f.write(f"\n<!-- {folder.name} -->\n{markdown}")
    return done.returncode, done.stdout + done.stderr, markdown


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--keep", metavar="DIR", help="play in DIR (kept) instead of a temporary folder")
    args = parser.parse_args()
    commands = workflow_commands(WORKFLOW.read_text())
    if set(commands) != {"main", "pull request"}:
        print(f"play_recipe: {WORKFLOW} has no main job or no pull-request command: {commands}")
        return 2
    failures: list[str] = []

    def expect(ok: bool, what: str, output: str) -> None:
        print(f"  {'ok' if ok else 'FAILED'}: {what}")
        if not ok:
            failures.append(what)
            print("\n".join("    | " + line for line in output.splitlines()[-40:]))

    with tempfile.TemporaryDirectory() as tmp:
        root = Path(args.keep) if args.keep else Path(tmp)
        root.mkdir(parents=True, exist_ok=True)
        summary = root / "job-summary.md"
        print(f"main: {shlex.join(commands['main'])}")
        main_folder = project(root, "main")
        code, output, _ = play(commands["main"], main_folder, summary)
        baseline = main_folder / ".specguard" / "baselines" / "main.json"
        expect(code == 0 and baseline.is_file(), "main passes and saves .specguard/baselines/main.json", output)
        for name in ("sabotaged", "unchanged", "renamed"):
            print(f"pull request ({name}): {shlex.join(commands['pull request'])}")
            folder = project(root, name)
            shutil.copytree(main_folder / ".specguard", folder / ".specguard")  # the workflow's cache restore
            code, output, markdown = play(commands["pull request"], folder, summary)
            if name == "sabotaged":
                expect(code == 1 and "dropped: 100% -> " in output, "the sabotaged spec fails the comparison", output)
                expect("### Compared with the baseline" in markdown, "the job summary says what was compared", output)
            elif name == "unchanged":
                expect(code == 0 and "unchanged: the same spec and runs" in output, "the unchanged spec passes", output)
                expect("[specguard] gate seed" not in output or "from cache" in output, "nothing trains", output)
            else:
                expect(
                    code == 0 and "unchanged within chance" in output, "the renamed spec is compared, passes", output
                )
        runs = summary.read_text().count("## specguard")
        print(f"job summary: {summary.stat().st_size} bytes of Markdown from {runs} runs")
    if failures:
        print(f"play_recipe: {len(failures)} step(s) did not do what the recipe promises: {'; '.join(failures)}")
        return 1
    print("play_recipe: every step did what the recipe promises")
    return 0


if __name__ == "__main__":
    sys.exit(main())
