"""The project's FMUs under the call-sequence fuzzer (tests/data/fuzz, tests/testkit/fuzz_run.py),
rebuilt from their own ``sources/`` with AddressSanitizer and UndefinedBehaviorSanitizer: a
short run per FMU kind and FMI version, the exact call sequences of every class of failure the
fuzzing found (cases.c), mutants the fuzzer must catch, and the long runs (``slow``)."""
import fcntl
import hashlib
import shutil
import tempfile
from pathlib import Path

import pytest
from fmpy.validation import validate_fmu
from testkit import fuzz_run

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="the sanitizer builds need gcc")

#: One FMU of each kind in the default run; the others in the slow one.
DEFAULT = [("plant", "cartpole"), ("estimator", "ekf"), ("signal", "sensor")]
OTHERS = [("plant", "iwp"), ("estimator", "mfiae"), ("signal", "prbs")]


def _sources_digest() -> str:
    """A digest of everything a fuzz build is made from (the package's code and C, the fuzz
    driver): sessions share a build only if they would build the same one."""
    root = Path(__file__).parents[2]
    h = hashlib.sha256()
    for p in sorted([*(root / "fmu_models").rglob("*"), *(root / "estimators").rglob("*.py"),
                     *(root / "tests" / "data").rglob("*"), root / "tests" / "testkit" / "fuzz_run.py"]):
        if p.is_file() and "__pycache__" not in p.parts:
            h.update(p.relative_to(root).as_posix().encode() + b"\0" + p.read_bytes())
    return h.hexdigest()[:16]


@pytest.fixture(scope="session")
def fuzz_targets(tmp_path_factory):
    """Build on demand, once per session (the test processes share the builds, one building
    while the others wait): target(label, version) -> fuzz_run.Target."""
    root = tmp_path_factory.getbasetemp().parent / f"fuzz-shared-{_sources_digest()}"
    tmp = root / "tmp"
    tmp.mkdir(parents=True, exist_ok=True)
    cache = {}

    def target(label, version):
        if (label, version) not in cache:
            with open(root / f"{label}-{version}.lock", "w") as lock:
                fcntl.flock(lock, fcntl.LOCK_EX)
                # the builds' temporary folders in a folder of this fixture, not in the shared
                # temporary folder that other tests watch for leftovers while this one builds
                old, tempfile.tempdir = tempfile.tempdir, str(tmp)
                try:
                    fmu = fuzz_run.build_fmu_for(label, version, root / "fmus")
                finally:
                    tempfile.tempdir = old
                cache[label, version] = fuzz_run.build_target(fmu, root / "build")
        return cache[label, version]

    return target


def _assert_clean(res):
    assert res.outcome == "ok", res.report
    c = res.counts
    assert c["illegal_error"] == c["illegal"] and c["legal_ok"] == c["legal"], c


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("kind,label", DEFAULT)
def test_a_short_fuzz_run_finds_nothing(fuzz_targets, kind, label, version):
    """300 seeded sequences: every forbidden call answered Error (with a message), every legal
    one OK, no sanitizer report, no hang; and the run reaches both kinds of call in volume."""
    res = fuzz_run.run(fuzz_targets(label, version), seed=7, first=0, count=300)
    _assert_clean(res)
    assert res.counts["sequences"] == 300
    assert res.counts["illegal"] > 2000 and res.counts["legal"] > 2000, res.counts


@pytest.mark.parametrize("case", fuzz_run.CASES)
@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("kind,label", DEFAULT)
def test_each_class_found_stays_fixed(fuzz_targets, kind, label, version, case):
    """The issue's findings as exact call sequences: non-finite and out-of-range times and steps
    (the estimator's doStep(t = inf) hang), value references >= 2^31 (signed overflow), FMI
    3.0 logging with loggingOn = false, eventModeUsed, calls after an Error, calls the state
    tables forbid (and directional derivatives in Terminated, allowed), FMU states freed, of
    another instance or changed, a NULL logger."""
    res = fuzz_run.run_case(fuzz_targets(label, version), case)
    assert res.outcome == "ok", res.report


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("kind,label", DEFAULT)
def test_the_fuzzed_fmus_validate(fuzz_targets, kind, label, version):
    assert validate_fmu(str(fuzz_targets(label, version).fmu)) == []


@pytest.mark.slow
def test_the_fuzzer_catches_a_missing_state_check(fuzz_targets, tmp_path):
    """A mutant whose fmi3DoStep skips the state check (allowed in every state): the fuzzer
    reports a forbidden call answered OK, with the replay command."""
    t = fuzz_targets("cartpole", 3)
    mutant = fuzz_run.build_target(t.fmu, tmp_path, mutate={
        "fmi3_wrapper.c": ('ALLOW(fn, CS_RUN, 0); (void)noSetPrior;', 'ALLOW(fn, ANY, ANY); (void)noSetPrior;')})
    res = fuzz_run.run(mutant, seed=7, first=0, count=300)
    assert res.outcome == "violation", res.report
    assert "fmi3DoStep" in res.report and "forbids was answered OK" in res.report
    assert "replay: PYTHONPATH=.:tests python -m testkit.fuzz_run" in res.report


def test_a_failing_sequence_replays_alone(fuzz_targets, capsys):
    """The replay command's entry point runs one sequence with its trace."""
    t = fuzz_targets("ekf", 2)
    assert fuzz_run.main([str(t.fmu), "--seed", "7", "--first", "12", "--count", "1", "--trace",
                          "--build-dir", str(t.lib.parents[1])]) == 0
    out = capsys.readouterr()
    assert "ok {'result': 'ok', 'sequences': 1" in out.out
    assert "fmi2Instantiate" in out.err                # the trace of the sequence


@pytest.mark.slow
def test_the_fuzzer_catches_an_unchecked_time(fuzz_targets, tmp_path):
    """A mutant estimator whose doStep checks neither the time nor the instant range (the code
    before the fix): doStep(t = inf) runs its update loop until the time limit (a hang), NaN
    is answered OK (a violation)."""
    t = fuzz_targets("ekf", 2)
    mutant = fuzz_run.build_target(t.fmu, tmp_path, mutate={"filter_core.c": [
        ("if (check_step(t, h, d->time, err)) return 1;", "(void)check_step;"),
        ("if (instant_of(t_end, d->t0, PERIOD, &k_end, err)) return 1;", "k_end = d->kc;")]})
    res = fuzz_run.run_case(mutant, "nonfinite_time", timeout=3)
    assert res.outcome in ("sanitizer", "hang", "violation"), res.report


@pytest.mark.slow
@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("kind,label", DEFAULT + OTHERS)
def test_a_long_fuzz_run_finds_nothing(fuzz_targets, kind, label, version):
    res = fuzz_run.run(fuzz_targets(label, version), seed=11, first=0, count=20000)
    _assert_clean(res)


@pytest.mark.slow
@pytest.mark.parametrize("case", fuzz_run.CASES)
@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("kind,label", OTHERS)
def test_each_class_stays_fixed_in_the_other_fmus(fuzz_targets, kind, label, version, case):
    res = fuzz_run.run_case(fuzz_targets(label, version), case)
    assert res.outcome == "ok", res.report


def test_an_fmi3_refusal_reaches_the_master_with_its_reason(fmu_builds):
    """FMI 3.0 FMUs log only with loggingOn (errors included): the master asks for it, so the
    named error still says why the FMU refused."""
    from cosim.components.sources import Constant
    from cosim.core.master import Cosimulation
    from cosim.fmi.fmu_component import FMUComponent
    from fmu_models.errors import CosimError

    plant = FMUComponent("p", fmu_builds["cartpole", 3], 0.01, parameters={"mc": -1.0})
    with pytest.raises(CosimError, match="parameter mc = -1 must be > 0"):
        Cosimulation([plant, Constant("f", 0.01, 0.1)], {"p.F": "f.out"}).run(0.05)
