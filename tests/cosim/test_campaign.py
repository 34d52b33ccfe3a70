"""Reduced seed 000 campaigns: metrics by hand, reproducibility, fast path equals master path,
the PCRB and the consistency verdicts of the reports."""
from dataclasses import replace

import numpy as np
import pytest

from cosim.experiments import metrics, seed000
from cosim.experiments.campaign import realisation_seeds, run_tasks
from estimators import chi2_band, nees_test, posterior_crb, rmse_ratio, whiteness_test
from fmu_models.errors import ConfigurationError, UnknownNameError

SMALL = seed000.Settings(runs=3, duration=0.5, scenarios=((0.2, 0.1), (0.3, 0.2)))


def test_metrics_equal_a_hand_computation():
    # 2 realisations, 2 steps, 2 states
    e = np.array([[[3.0, 4.0], [0.0, 0.0]],
                  [[1.0, 1.0], [6.0, 8.0]]])
    # RMS over states: run 0: [sqrt(12.5), 0]; run 1: [1, sqrt(50)]
    r = np.array([[np.sqrt(12.5), 0.0], [1.0, np.sqrt(50.0)]])
    np.testing.assert_allclose(metrics.eps_k(e), r.mean(axis=0))            # eq 43
    assert metrics.eta(e) == pytest.approx(r.mean())                        # eq 44
    np.testing.assert_allclose(metrics.eta_per_run(e), r.mean(axis=1))
    np.testing.assert_allclose(metrics.rmse_per_state(e), np.sqrt([(9 + 0 + 1 + 36) / 4, (16 + 0 + 1 + 64) / 4]))
    assert metrics.diverged(e, 7.0).tolist() == [False, True]
    e[0, 1, 0] = np.nan
    assert metrics.diverged(e, 100.0).tolist() == [True, False]
    P = np.broadcast_to(np.diag([1.0, 4.0]), (2, 2, 2, 2))
    np.testing.assert_allclose(metrics.nees(np.ones((2, 2, 2)), P), 1.25)


def test_seeds_depend_only_on_their_key():
    a = realisation_seeds(7, 1, 2)
    assert a == realisation_seeds(7, 1, 2) and a != realisation_seeds(7, 2, 1)
    assert len(set(a)) == 2


def _etas(per_run):
    return per_run.sort_values(["reading", "scenario", "filter", "run"])["eta"].to_numpy()


@pytest.mark.slow
def test_campaign_is_reproducible_and_order_independent():
    a = seed000.run(SMALL, readings=("eqs",), backend="serial", progress=False)[0]
    b = seed000.run(SMALL, readings=("eqs",), backend="processes", n_jobs=2, progress=False)[0]
    np.testing.assert_array_equal(_etas(a), _etas(b))
    # a realisation does not depend on which others run with it
    one = seed000.fast_task(1, "eqs", SMALL, runs=[2])
    np.testing.assert_allclose(one["per_run"]["MF-IAE"]["eta"],
                               a[(a.scenario == 2) & (a["filter"] == "MF-IAE") & (a.run == 2)]["eta"],
                               rtol=1e-13)
    c = seed000.run(seed000.Settings(runs=3, duration=0.5, scenarios=SMALL.scenarios, seed=1),
                    readings=("eqs",), backend="serial", progress=False)[0]
    assert not np.allclose(_etas(a), _etas(c))


@pytest.mark.parametrize("reading", ["eqs", pytest.param("prose", marks=pytest.mark.slow)])
def test_fast_path_equals_master_path_with_the_plant_fmu(reading):
    fast = seed000.fast_task(0, reading, SMALL)
    master = seed000.master_task(0, reading, SMALL)
    for name in seed000.FILTERS:
        np.testing.assert_allclose(fast["per_run"][name]["eta"], master["per_run"][name]["eta"],
                                   rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(fast["eps_k"][name], master["eps_k"][name], rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(fast["per_run"][name]["anis"], master["per_run"][name]["anis"],
                                   rtol=1e-9)
        for stat in ("nees", "nis", "mse"):
            np.testing.assert_allclose(fast["steps"][name][stat], master["steps"][name][stat], rtol=1e-8, atol=1e-12)
        assert master["whiteness"][name]["white_ok"] is None and fast["whiteness"][name]["white_ok"] is not None


@pytest.mark.slow
def test_report_is_written(tmp_path):
    result = seed000.run(SMALL, backend="serial", progress=False)
    md = seed000.write_report(result, SMALL, tmp_path, "fast")
    text = md.read_text()
    assert "Table 3" in text and "| q0 |" in text and "prose" in text and "4.4782" in text
    assert "Where we agree with the paper" in text and (tmp_path / "settings.toml").exists()
    assert "posterior Cramér-Rao bound" in text and "Rule: consistent at 95%" in text
    assert "3 realisations x 2 scenarios" in text and "Regime: configuration custom" in text
    table = [ln for ln in text.splitlines() if ln.startswith("| reading | scenario | filter | runs")]
    body = text.splitlines()[text.splitlines().index(table[0]):][:2 + 2 * 2 * len(seed000.FILTERS)]
    assert len({ln.count("|") for ln in body}) == 1                 # a well-formed markdown table
    for name in ("per_run.csv", "per_run.parquet", "eps_k.csv", "table3.csv", "consistency.csv", "pcrb.csv",
                 "figure3_eqs.png", "figure4_prose.png", "figure_nees_eqs.png", "figure_nis_prose.png",
                 "figure_rmse_pcrb_eqs.png"):
        assert (tmp_path / name).exists(), name
    assert len(result.per_run) == 2 * 2 * len(seed000.FILTERS) * 3
    # one row per reading, scenario and filter, and one for the PCRB
    assert len(result.consistency) == 2 * 2 * (len(seed000.FILTERS) + 1)
    assert len(result.bound) == 2 * 2 * (SMALL.steps + 1)


def test_campaign_pcrb_and_verdicts_equal_the_estimators_functions():
    """The campaign's bound is posterior_crb on its own truth (known initial state); its
    RMSE / PCRB equals estimators.rmse_ratio on the errors; its band and whiteness numbers
    are nees_test / whiteness_test on the filter's own outputs."""
    res = seed000.fast_task(1, "eqs", SMALL)
    q, r = seed000.true_noise(SMALL.scenarios[1], "eqs")
    X, Y, u = seed000.simulate_truth(SMALL, q, r, [tuple(realisation_seeds(SMALL.seed, 1, k)) for k in range(3)])
    bound = posterior_crb(seed000._system(SMALL.T), X, u[:-1, None], q, r)
    np.testing.assert_allclose(res["bound"], bound.mse, rtol=1e-13)
    assert not res["bound"][0].any()
    from cosim.experiments.common import batch_run

    make = seed000.make_filters(seed000._system(SMALL.T), SMALL, q, r, res["learned"])["SWML"]
    out = batch_run(make, X, Y, u[:, None])
    ratio = metrics.pcrb_ratio(res["per_run"]["SWML"]["rmse"], res["bound"][1:])
    np.testing.assert_allclose(ratio, rmse_ratio(out.x - X, bound), rtol=1e-12)
    row, per_step = metrics.band_row(res["steps"]["SWML"]["nees"], res["steps"]["SWML"]["nis"], 4, 2)
    ref = nees_test(out.nees, 4)
    assert row["anees"] == pytest.approx(ref.average, rel=1e-12) and (row["anees_lo"], row["anees_hi"]) == ref.band
    assert ref.band == chi2_band(3, 4)
    np.testing.assert_allclose(per_step["anees"], out.nees.mean(axis=0), rtol=1e-12)
    w = whiteness_test(out.innovation, out.S, lags=range(1, 6))
    assert res["whiteness"]["SWML"]["acf_max"] == pytest.approx(np.abs(w.autocorrelation).max(), rel=1e-12)
    assert res["whiteness"]["SWML"]["white_ok"] == w.white
    # the filters' own prior instead of the known start
    other = seed000.scenario_bound(replace(SMALL, pcrb_prior="P0"), X, u, q, r)
    np.testing.assert_allclose(other, posterior_crb(seed000._system(SMALL.T), X, u[:-1, None], q, r, SMALL.P0).mse)
    assert (other[1:] >= res["bound"][1:]).all()             # less known at the start: a higher bound


@pytest.mark.slow
def test_master_path_campaign_has_the_same_bound_and_bands():
    s = replace(SMALL, runs=2, duration=0.3, scenarios=SMALL.scenarios[:1], readings=("eqs",))
    fast = seed000.run(s, backend="serial", progress=False).consistency
    master = seed000.run(s, path="master", backend="serial", progress=False).consistency
    cols = ["rmse_x", "pcrb_ratio_x", "pcrb_ratio_theta_dot", "anees", "anees_lo", "anis", "anis_inside"]
    np.testing.assert_allclose(master[cols].to_numpy(float), fast[cols].to_numpy(float), rtol=1e-8)
    filt = master["filter"] != "PCRB"
    assert master.loc[filt, "white_ok"].isna().all() and fast.loc[filt, "white_ok"].notna().all()


def test_settings_of_the_limit_and_the_bands_are_checked():
    with pytest.raises(UnknownNameError, match="pcrb_prior must be one of"):
        seed000.Settings(pcrb_prior="guess")
    for bad in (0.0, 1.0, 1.5, -0.5):
        with pytest.raises(ConfigurationError, match="confidence must lie strictly between 0 and 1"):
            seed000.Settings(confidence=bad)
    with pytest.raises(ConfigurationError, match="whiteness_lags"):
        seed000.Settings(whiteness_lags=0)
    # the campaign's own checks still run after these
    with pytest.raises(ConfigurationError, match="q0"):
        seed000.Settings(q0=-1.0)
    with pytest.raises(ConfigurationError, match="x0 must have 4 entries"):
        seed000.Settings(x0=(0.0, 1.0))
    assert not seed000.Settings(duration=0.5).has_late and seed000.Settings().has_late
    with pytest.raises(ConfigurationError, match="shorter than the 50 steps"):
        seed000.Settings(duration=0.5, whiteness_lags=50)
    with pytest.raises(ConfigurationError, match="transient_steps"):
        seed000.Settings(transient_steps=-1)


def test_run_tasks_refuses_unknown_backend():
    with pytest.raises(ValueError, match="backend"):
        run_tasks([], backend="threads")


@pytest.mark.slow
def test_full_seed000_campaign_reproduces_the_bound():
    """Full campaign (100 realisations, both readings): the EKF with the true Q and R is
    consistent (ANEES ~ 4, ANIS ~ 2) and no filter diverges."""
    per_run = seed000.run(seed000.Settings(), progress=False)[0]
    true = per_run[per_run["filter"] == "EKF true Q,R"]
    assert true["anees"].mean() == pytest.approx(4.0, rel=0.05)
    assert true["anis"].mean() == pytest.approx(2.0, rel=0.05)
    assert not per_run["diverged"].any()


def test_seed001_fast_equals_master_and_kf_diverges_only_far_from_its_linearisation():
    from cosim.experiments import seed001

    s = seed001.Settings(runs=2, duration=3.0)
    for case in seed001.CASES:
        fast = seed001.fast_task(case, s)
        master = seed001.master_task(case, s)
        np.testing.assert_allclose(fast["bound"], master["bound"], rtol=1e-12)
        for n in seed001.FILTERS:
            np.testing.assert_allclose(fast[n]["rmse"], master[n]["rmse"], rtol=1e-10, atol=1e-13)
            np.testing.assert_allclose(fast[n]["pcrb_ratio"], master[n]["pcrb_ratio"], rtol=1e-8)
            for key in ("anees", "anis", "anees_inside"):
                assert fast[n]["tests"][key] == pytest.approx(master[n]["tests"][key], rel=1e-6), key
            assert master[n]["tests"]["white_ok"] is None and fast[n]["tests"]["white_ok"] is not None
    up = seed001.fast_task("upright", s)
    assert np.isfinite(up["KF"]["t_div"]).all() and not np.isfinite(up["EKF"]["t_div"]).any()
    hang = seed001.fast_task("hanging", s)
    assert not np.isfinite(hang["KF"]["t_div"]).any()


@pytest.mark.slow
def test_seed001_report_has_the_pcrb_and_the_verdicts(tmp_path):
    from cosim.experiments import seed001

    s = seed001.Settings(runs=3, duration=2.0)
    result = seed001.run(s, backend="serial", progress=False)
    cons = result.consistency
    assert list(cons["filter"]) == ["KF", "EKF", "PCRB"] * 2
    hanging = cons[(cons.case == "hanging") & (cons["filter"] == "EKF")].iloc[0]
    assert 0.5 < hanging["pcrb_ratio_x"] < 2.0 and hanging["consistent"] in (True, False)
    upright_kf = cons[(cons.case == "upright") & (cons["filter"] == "KF")].iloc[0]
    assert upright_kf["pcrb_ratio_max"] > 10 and not upright_kf["consistent"]       # it diverges
    md = seed001.write_report(result, s, tmp_path)
    text = md.read_text()
    assert "posterior Cramér-Rao bound" in text and "Rule: consistent at 95%" in text and "Regime:" in text
    for name in ("consistency.csv", "errors.png", "nees.png", "rmse_pcrb.png", "settings.toml"):
        assert (tmp_path / name).exists(), name
    with pytest.raises(UnknownNameError, match="pcrb_prior"):
        seed001.Settings(pcrb_prior="x")


@pytest.mark.slow
def test_dask_backend_gives_the_same_numbers():
    """The campaign on a local dask.distributed cluster equals the serial run."""
    a = seed000.run(SMALL, readings=("eqs",), backend="dask", n_jobs=2, progress=False)[0]
    b = seed000.run(SMALL, readings=("eqs",), backend="serial", progress=False)[0]
    np.testing.assert_array_equal(_etas(a), _etas(b))


def test_partial_campaign_keeps_what_finished(tmp_path):
    """An interrupted campaign (some tasks None): the finished scenarios keep their rows; on
    the master path (several chunks, the PCRB in its own task) a scenario whose PCRB task
    did not finish has no ratio (NaN, not a wrong one) and no whiteness; the report says
    PARTIAL."""
    s = replace(SMALL, readings=("eqs",))
    keys = [("eqs", 0), ("eqs", 1)]
    done = seed000.fast_task(0, "eqs", s)
    res = seed000._assemble(s, keys, [np.arange(3)], [done, None], 1.0)
    assert set(res.consistency["scenario"]) == {1} and set(res.per_run["scenario"]) == {1}
    assert res.consistency["runs"].eq(3).all()
    master = {**done, "whiteness": {n: metrics.no_whiteness() for n in done["whiteness"]}}   # what a master task
    master.pop("bound")                                                                     # returns
    res = seed000._assemble(s, keys, [np.arange(3)], [master, None, None, None], 1.0)
    row = res.consistency[res.consistency["filter"] == "SWML"].iloc[0]
    assert np.isnan(row["pcrb_ratio_x"]) and row["white_ok"] is None
    assert row["anees"] == pytest.approx(done["steps"]["SWML"]["nees"].mean(), rel=1e-12)
    assert "PCRB" not in set(res.consistency["filter"]) and not len(res.bound)
    md = seed000.write_report(res, s, tmp_path, "master", partial=True).read_text()
    assert "PARTIAL RESULTS" in md and "whiteness is not tested there" in md


@pytest.mark.parametrize(("setting", "message"), [("confidence=2", "confidence must lie strictly between 0 and 1"),
                                                  ("pcrb_prior=guess", "pcrb_prior must be one of"),
                                                  ("whiteness_lags=0", "whiteness_lags must be an integer >= 1"),
                                                  ("transient_steps=-1", "transient_steps must be an integer >= 0")])
def test_bad_limit_settings_are_refused_on_the_command_line(tmp_path, capsys, setting, message):
    from cosim.cli import main

    for experiment in ("seed000", "seed000-sweep"):
        assert main(["experiment", experiment, "--set", setting, "--out", str(tmp_path / "o")]) == 2
        err = capsys.readouterr().err
        assert message in err and "Traceback" not in err and not (tmp_path / "o").exists()


@pytest.mark.parametrize("name, settings", [("seed001", ["--set", "duration=2"]),
                                            ("seed002", ["--set", "duration=1"])])
def test_an_interrupted_campaign_writes_a_partial_report(tmp_path, capsys, monkeypatch, name, settings):
    """Ctrl-C after the first task: the command line writes the finished part as a report that
    says PARTIAL, and exits 130."""
    from cosim.cli import main
    from cosim.experiments import common
    from fmu_models.errors import Interrupted

    def first_task_only(tasks, **kw):
        fn, args = tasks[0]
        raise Interrupted("interrupted after the first task", [fn(**args)] + [None] * (len(tasks) - 1))

    monkeypatch.setattr(common, "run_tasks", first_task_only)
    assert main(["experiment", name, "--runs", "2", *settings, "--backend", "serial", "--quiet",
                 "--out", str(tmp_path / "o")]) == 130
    err = capsys.readouterr().err
    assert "Traceback" not in err and "partial results" in err
    assert "PARTIAL RESULTS" in (tmp_path / "o" / "summary.md").read_text()
