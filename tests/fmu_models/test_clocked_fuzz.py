"""The clocked FMUs (the estimator's and a signal's clocked form, FMI 3.0) under the
call-sequence fuzzer (tests/data/fuzz, its clocked kind), rebuilt from their own ``sources/``
with AddressSanitizer and UndefinedBehaviorSanitizer: Co-Simulation with Event Mode and
Scheduled Execution instances driven through the clock's call sequences and hostile calls;
mutants without one of the clock's checks must be caught."""
import shutil

import pytest
from testkit import fuzz_run

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="the sanitizer builds need gcc")

LABELS = fuzz_run.FMU_KINDS["clocked"]


@pytest.fixture(scope="module")
def clocked_targets(tmp_path_factory):
    root = tmp_path_factory.mktemp("clocked-fuzz")
    cache = {}

    def target(label):
        if label not in cache:
            fmu = fuzz_run.build_fmu_for(label, 3, root / "fmus")
            cache[label] = fuzz_run.build_target(fmu, root / "build")
        return cache[label]

    return target


def _assert_clean(res):
    assert res.outcome == "ok", res.report
    c = res.counts
    assert c["illegal_error"] == c["illegal"] and c["legal_ok"] == c["legal"], c


@pytest.mark.parametrize("label", [LABELS[0], pytest.param(LABELS[1], marks=pytest.mark.slow)])
def test_a_short_fuzz_of_the_clocked_fmus_finds_nothing(clocked_targets, label):
    t = clocked_targets(label)
    assert t.clock == (t.clock[0], 0.01)
    res = fuzz_run.run(t, seed=7, first=0, count=300)
    _assert_clean(res)
    assert res.counts["sequences"] == 300
    assert res.counts["illegal"] > 1000 and res.counts["legal"] > 3000, res.counts


def test_the_clocked_fmus_are_fmi3_only():
    with pytest.raises(ValueError, match="the clocked form needs FMI 3.0"):
        fuzz_run.build_fmu_for("ekf_clocked", 2, "unused")


STEP_MODE_CHECK = '    if (c->d.clk.active)\n        return fail(c, "fmi3EnterStepMode"'
DUE_CHECK = "    switch (core_clock_due(&c->d, t)) {"
MUTANTS = {
    "Step Mode while the clock is active": ("fmi3_wrapper.c", STEP_MODE_CHECK,
                                            STEP_MODE_CHECK.replace("c->d.clk.active", "0")),
    "a step past the activation": ("fmi3_wrapper.c", "if (core_clock_due(&c->d, t + h) == 2)", "if (0)"),
    "a get after a set in Scheduled Execution": ("fmi3_wrapper.c", "if (set || c->d.clk.fresh) continue;",
                                                 "continue;"),
    "a clock set when not due": ("fmi3_wrapper.c", DUE_CHECK, "    switch (1) {"),
}


#: The mutants of the default run; the others in the slow one (each is a sanitizer build).
DEFAULT_MUTANTS = ("Step Mode while the clock is active", "a get after a set in Scheduled Execution")


@pytest.mark.parametrize("mutant", [m if m in DEFAULT_MUTANTS else pytest.param(m, marks=pytest.mark.slow)
                                    for m in MUTANTS])
def test_the_fuzzer_catches_a_missing_clock_check(clocked_targets, tmp_path, mutant):
    source, text, replacement = MUTANTS[mutant]
    t = clocked_targets("ekf_clocked")
    broken = fuzz_run.build_target(t.fmu, tmp_path, mutate={source: (text, replacement)})
    res = fuzz_run.run(broken, seed=7, first=0, count=300)
    assert res.outcome == "violation", (res.outcome, res.counts)
    assert "a call the standard forbids was answered OK" in res.report


@pytest.mark.slow
@pytest.mark.parametrize("label", LABELS)
def test_a_long_fuzz_of_the_clocked_fmus_finds_nothing(clocked_targets, label):
    res = fuzz_run.run(clocked_targets(label), seed=11, first=0, count=20000)
    _assert_clean(res)
