"""Every verdict word specguard says, and the one mapping between them.

Each door (the API's :class:`~specguard.engine.spec_result.SpecResult`,
``specguard run``, the pytest plugin's items, reports and JUnit properties,
``specguard reproduce``, the baseline gate) reads its words from here, so a
goal is called the same everywhere. From the bottom up:

* a **run** against a goal's threshold: :class:`RunVerdict` (met, missed, undecided);
* a goal over its runs, against a quorum: :class:`QuorumVerdict` (passed, failed, open);
* the goal at the end: :class:`GoalOutcome` (passed, failed, undecided: failed
  only through runs that stayed undecided), from :func:`goal_outcome`;
* what the goal **counts as** (:func:`counted`): pytest's item outcome, one of
  :data:`COUNTED` (passed, xfailed, failed); the spec's ``undecided``
  (:data:`UNDECIDED_AS`) and ``xfail`` apply there and nowhere else;
* the **word** shown for it (:func:`verdict_word`): one of :class:`Word`,
  pytest's words and ``undecided``, worst first; and the spec's own word
  (:func:`spec_word`), its goals' worst, or :data:`SPEC_FAILED`.

Example:
    >>> outcome = goal_outcome(QuorumVerdict.FAILED, [RunVerdict.UNDECIDED], crashed=False)
    >>> outcome, counted(outcome, crashed=False, undecided_as="xfail")
    (<GoalOutcome.UNDECIDED: 'undecided'>, <Word.XFAILED: 'xfailed'>)
    >>> verdict_word(Word.PASSED, outcome), verdict_word(Word.PASSED, GoalOutcome.PASSED, expected_miss=True)
    (<Word.UNDECIDED: 'undecided'>, <Word.XPASSED: 'xpassed'>)
    >>> spec_word([Word.PASSED, Word.UNDECIDED], crashed=False, undecided_counts_as=Word.FAILED)
    'undecided, counted as failed'
"""

from __future__ import annotations

import enum
from collections.abc import Mapping, Sequence

__all__ = [
    "COUNTED",
    "DEFAULT_UNDECIDED",
    "FAILING_WORDS",
    "OUTCOME_VERBS",
    "SPEC_FAILED",
    "UNDECIDED_AS",
    "UNDECIDED_OUTCOMES",
    "VERDICT_WORDS",
    "GoalOutcome",
    "QuorumVerdict",
    "RunVerdict",
    "Word",
    "counted",
    "goal_outcome",
    "pytest_counted",
    "spec_word",
    "verdict_word",
]


class RunVerdict(enum.StrEnum):
    """One run against one goal's threshold (:func:`specguard.stats.intervals.run_verdict`)."""

    MET = "met"
    MISSED = "missed"
    UNDECIDED = "undecided"  # the run's interval straddles the threshold: more episodes could decide it


class QuorumVerdict(enum.StrEnum):
    """A goal over its runs (:func:`specguard.stats.intervals.quorum_verdict`)."""

    PASSED = "passed"
    FAILED = "failed"
    OPEN = "open"  # neither is settled yet: more runs could decide it


class GoalOutcome(enum.StrEnum):
    """A goal at the end (:func:`goal_outcome`): passed, failed, or undecided (failed only through undecided runs)."""

    PASSED = "passed"
    FAILED = "failed"
    UNDECIDED = "undecided"


class Word(enum.StrEnum):
    """The word every door shows for a goal, worst first: pytest's outcomes, and ``undecided``."""

    FAILED = "failed"
    UNDECIDED = "undecided"
    XFAILED = "xfailed"
    XPASSED = "xpassed"
    PASSED = "passed"


VERDICT_WORDS: tuple[Word, ...] = tuple(Word)
"""The words, worst first: a spec's word is its goals' worst (:func:`spec_word`)."""

COUNTED: tuple[Word, ...] = (Word.PASSED, Word.XFAILED, Word.FAILED)
"""What a goal can count as (:func:`counted`): the outcome of its pytest item, which decides the exit status."""

UNDECIDED_AS: Mapping[str, Word] = {"fail": Word.FAILED, "xfail": Word.XFAILED, "pass": Word.PASSED}
"""What a goal whose runs stayed undecided counts as, per ``Spec.undecided`` (and every door's option)."""

DEFAULT_UNDECIDED = "fail"
"""What an undecided goal counts as unless a spec or a door says otherwise."""

UNDECIDED_OUTCOMES: tuple[str, ...] = tuple(UNDECIDED_AS)
"""The values ``Spec.undecided``, ``specguard run --undecided`` and ``--goal-specs-undecided`` take."""

FAILING_WORDS: frozenset[Word] = frozenset({Word.FAILED, Word.UNDECIDED})
"""The words of goals a report lists as failing: they did not pass, and were not expected to miss."""

SPEC_FAILED = "FAILED"
"""A spec's word when a seed crashed or a goal failed (``specguard run``'s ``== name:`` line)."""

OUTCOME_VERBS: Mapping[GoalOutcome, str] = {
    GoalOutcome.PASSED: "met",
    GoalOutcome.FAILED: "missed",
    GoalOutcome.UNDECIDED: "could not be decided for",
}
"""How a goal's message says its outcome: "goal 'up' of spec 'p' {verb} its threshold"."""


def goal_outcome(verdict: QuorumVerdict, runs: Sequence[RunVerdict], *, crashed: bool) -> GoalOutcome:
    """A goal at the end, from its quorum ``verdict`` and its runs' verdicts.

    Passed when the quorum passed; undecided when it did not, only through runs
    that stayed undecided (none missed, no seed ``crashed``: more evaluation
    episodes could have decided it); failed otherwise.

    Example:
        >>> goal_outcome(QuorumVerdict.FAILED, [RunVerdict.MET, RunVerdict.MISSED], crashed=False)
        <GoalOutcome.FAILED: 'failed'>
    """
    if verdict is QuorumVerdict.PASSED:
        return GoalOutcome.PASSED
    if not crashed and runs and RunVerdict.MISSED not in runs:
        return GoalOutcome.UNDECIDED
    return GoalOutcome.FAILED


def counted(
    outcome: GoalOutcome, *, crashed: bool, undecided_as: str = DEFAULT_UNDECIDED, expected_miss: bool = False
) -> Word:
    """What a goal counts as at every door: passed, xfailed or failed (:data:`COUNTED`).

    The one place the spec's ``undecided`` and ``xfail`` apply: an undecided goal
    counts as ``undecided_as`` says (:data:`UNDECIDED_AS`); a goal expected to
    miss (``xfail``) that did not pass counts as xfailed, unless runs
    ``crashed``: a crash is not a miss, so the goal counts as failed.

    Raises:
        ValueError: ``undecided_as`` is none of :data:`UNDECIDED_OUTCOMES`.

    Example:
        >>> counted(GoalOutcome.FAILED, crashed=False, expected_miss=True)
        <Word.XFAILED: 'xfailed'>
        >>> counted(GoalOutcome.FAILED, crashed=True, expected_miss=True)
        <Word.FAILED: 'failed'>
    """
    if undecided_as not in UNDECIDED_AS:
        raise ValueError(f"expected undecided_as to be one of {UNDECIDED_OUTCOMES}, got {undecided_as!r}")
    if outcome is GoalOutcome.PASSED:
        return Word.PASSED
    if crashed:
        return Word.FAILED
    as_undecided = UNDECIDED_AS[undecided_as] if outcome is GoalOutcome.UNDECIDED else Word.FAILED
    if as_undecided is Word.PASSED:
        return Word.PASSED
    return Word.XFAILED if expected_miss else as_undecided


def verdict_word(counts_as: str, outcome: str, *, expected_miss: bool = False) -> Word:
    """The word shown for a goal: pytest's (passed, failed, xfailed, xpassed), or undecided.

    The one rule ``specguard run``'s table and the pytest plugin's rows both follow.

    Args:
        counts_as: what the goal counts as (:func:`counted`; in pytest, :func:`pytest_counted`).
        outcome: the goal's :class:`GoalOutcome`.
        expected_miss: the spec declares the goal in ``xfail``: passing it is ``xpassed``, as a
            non-strict ``pytest.mark.xfail`` that passes.

    An undecided goal that counts as passed or failed says ``undecided`` (what it
    counts as decides the exit status); one that counts as xfailed is ``xfailed``,
    as pytest reports it.

    Raises:
        ValueError: ``counts_as`` is none of :data:`COUNTED`, or ``outcome`` no :class:`GoalOutcome`.

    Example:
        >>> verdict_word("xfailed", "failed"), verdict_word("failed", "undecided")
        (<Word.XFAILED: 'xfailed'>, <Word.UNDECIDED: 'undecided'>)
    """
    word = Word(counts_as)
    if word not in COUNTED:
        raise ValueError(f"expected counts_as to be one of {[str(w) for w in COUNTED]}, got {counts_as!r}")
    if word is Word.PASSED and expected_miss:
        return Word.XPASSED
    if GoalOutcome(outcome) is GoalOutcome.UNDECIDED and word is not Word.XFAILED:
        return Word.UNDECIDED
    return word


def pytest_counted(outcome: str, *, expected_miss: bool) -> Word:
    """What a goal counted as, read from its pytest item's report: its ``outcome``, and whether it ``wasxfail``.

    pytest reports an xfailed item as ``"skipped"`` with ``wasxfail``, and an xpassed one as ``"passed"``.

    Example:
        >>> pytest_counted("skipped", expected_miss=True), pytest_counted("passed", expected_miss=True)
        (<Word.XFAILED: 'xfailed'>, <Word.PASSED: 'passed'>)
    """
    if expected_miss and outcome != Word.PASSED:
        return Word.XFAILED
    return Word(outcome)


def spec_word(words: Sequence[Word], *, crashed: bool, undecided_counts_as: Word | None = None) -> str:
    """A spec's word at the end: :data:`SPEC_FAILED` when a seed crashed, else its goals' worst word.

    A failed goal makes it :data:`SPEC_FAILED`; an undecided one says what it counts as
    (``undecided_counts_as``, :func:`counted`), which decides the exit status.

    Example:
        >>> spec_word([Word.XFAILED, Word.PASSED], crashed=False), spec_word([], crashed=True)
        ('xfailed', 'FAILED')
    """
    if crashed:
        return SPEC_FAILED
    worst = min(words, key=VERDICT_WORDS.index, default=Word.PASSED)
    if worst is Word.FAILED:
        return SPEC_FAILED
    if worst is Word.UNDECIDED:
        return f"{worst}, counted as {undecided_counts_as or Word.FAILED}"
    return str(worst)
